//! `fleet run` end to end: the world-server and the agents as separate processes, observed by
//! the orchestrator; results, determinism, faults, interruption and cleanup.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use serde_json::Value;
use tests::{
    ChildGuard, EXIT_TIMEOUT, TestRun, binary, fleet_run, processes_mentioning, wait_until,
};

/// The 2-UAV small-region scenario of the tests, with a camera large enough to identify cars.
fn scenario(duration_s: f64, uavs: u32) -> String {
    format!(
        "seed = 3\nduration_s = {duration_s}\n\n[region]\nhalf_extent_m = 100.0\n\n\
         [targets]\ncount = 4\n\n[uavs]\ncount = {uavs}\n\n[camera]\nrows = 120\ncols = 160\n"
    )
}

/// Runs to the end (bounded) and checks that nothing of the run is left.
fn finish(t: &TestRun, mut fleet: ChildGuard) -> Output {
    let out = fleet
        .wait_timeout(EXIT_TIMEOUT)
        .expect("fleet run did not end in time");
    assert_nothing_left(t);
    out
}

fn assert_nothing_left(t: &TestRun) {
    wait_until(
        "the run's processes to exit",
        Duration::from_secs(10),
        || processes_mentioning(t.run.as_str()).is_empty(),
    );
    assert!(t.ipc_files().is_empty(), "files left: {:?}", t.ipc_files());
}

fn summary(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn a_small_fleet_runs_end_to_end_as_processes() {
    let t = TestRun::new("run-e2e");
    let file = t.write("scenario.toml", &scenario(60.0, 2));
    let out_dir = t.dir.join("out");
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &["--strict"])),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let s = summary(&out_dir);
    let steps = 120;
    assert_eq!(s["steps"], steps, "{s}");
    assert_eq!(s["violations"], 0, "{s}");
    assert_eq!(s["interrupted"], false);
    assert_eq!(s["variant"], "paper", "the default variant is recorded");
    for a in s["agents"].as_array().expect("agents") {
        assert_eq!(a["steps_processed"], steps, "an agent missed steps: {a}");
        assert_eq!(a["restarts"], 0);
        assert!(a["decisions"].as_u64().expect("decisions") > 0, "{a}");
    }
    assert!(
        s["identified_final"].as_f64().expect("identified") >= 1.0,
        "{s}"
    );
    let csv = std::fs::read_to_string(out_dir.join("timeseries.csv")).expect("timeseries");
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows.len(), steps + 1, "one row per step after the header");
    let ua_column = rows[0]
        .split(',')
        .position(|c| c == "ua")
        .expect("ua column");
    let ua = |row: &str| -> f64 { row.split(',').nth(ua_column).unwrap().parse().unwrap() };
    let (first, last) = (ua(rows[1]), ua(rows[steps]));
    assert!(last < first, "UA did not fall: {first} -> {last}");
    assert_eq!(s["ua_final"].as_f64(), Some(last));
    for picture in ["metrics.png", "map.png", "sets.png"] {
        let bytes = std::fs::read(out_dir.join(picture)).expect(picture);
        assert!(
            bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000,
            "{picture}"
        );
    }
    for key in ["frames", "estimates", "tokens", "truth"] {
        assert!(
            s["comms"][key]["bytes"].as_u64().unwrap_or(0) > 0,
            "comms {key}: {s}"
        );
    }
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("violations") && table.contains("UA (final)"),
        "{table}"
    );
}

/// The summary without what depends on the wall clock or the load (`wall_s`,
/// `real_time_factor` and everything under a `timing` or `resources` key).
fn without_wall_clock(mut v: Value) -> Value {
    fn strip(v: &mut Value) {
        match v {
            Value::Object(map) => {
                map.remove("wall_s");
                map.remove("real_time_factor");
                map.remove("timing");
                map.remove("resources");
                map.values_mut().for_each(strip);
            }
            Value::Array(items) => items.iter_mut().for_each(strip),
            _ => {}
        }
    }
    strip(&mut v);
    v
}

/// Runs the 20 s 2-UAV scenario with `args` to a successful end; returns its summary without
/// the wall clock and its `timeseries.csv`.
fn two_uav_run(topic: &str, args: &[&str]) -> (Value, String) {
    let t = TestRun::new(topic);
    let file = t.write("scenario.toml", &scenario(20.0, 2));
    let out_dir = t.dir.join("out");
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, args)),
    );
    assert!(out.status.success(), "{args:?}: {}", stderr(&out));
    let csv = std::fs::read_to_string(out_dir.join("timeseries.csv")).expect("csv");
    (without_wall_clock(summary(&out_dir)), csv)
}

#[test]
fn the_same_seed_in_lockstep_gives_the_same_results() {
    // `paper`, `kappa0` and `nomap` share the paper's planner; `setfleet` has its own. Lossy,
    // slow, range-limited links lose the same messages with the same seed (drawn from it and
    // the UAVs' poses, never from timing) and never wait for them. Both exchanges: measurements are applied in a fixed order
    // whatever order they came in.
    let lossy = ["--set", "comms.loss=0.3", "--set", "comms.latency_ms=700"];
    let measurements = ["--set", "comms.exchange=measurements"];
    let lossy_measurements = [&lossy[..], &measurements[..]].concat();
    // The 2 UAVs start 133 m apart: beyond range until they meet, tokens and liveness through
    // the radio only (the readings' defaults).
    let limited = ["--set", "comms.range_m=80"];
    for (variant, links) in [
        ("paper", &[][..]),
        ("setfleet", &[]),
        ("setfleet", &limited[..]),
        ("paper", &lossy[..]),
        ("paper", &measurements[..]),
        ("paper", &lossy_measurements[..]),
    ] {
        let args = [&["--variant", variant][..], links].concat();
        let results: Vec<(Value, String)> = (0..2)
            .map(|_| two_uav_run("run-determinism", &args))
            .collect();
        assert_eq!(
            results[0].1, results[1].1,
            "{variant} {links:?}: timeseries.csv differs"
        );
        assert_eq!(
            results[0].0, results[1].0,
            "{variant} {links:?}: summary.json differs"
        );
        if links.contains(&"comms.loss=0.3") {
            let agents = results[0].0["agents"].as_array().expect("agents");
            let lost: u64 = agents
                .iter()
                .map(|a| a["estimates_lost"].as_u64().unwrap())
                .sum();
            assert!(lost > 0, "the lossy runs lost nothing");
        }
    }
}

/// `estimator.window_m`: a window over the whole region gives the run without one byte for
/// byte (sets and metrics), and windows smaller than the region keep the guarantee, under both
/// exchanges.
#[test]
fn windows_over_the_region_change_nothing_and_smaller_ones_keep_the_guarantee() {
    for exchange in ["measurements", "sets"] {
        let run = |window_m: &str| {
            let exchange = format!("comms.exchange={exchange}");
            let window = format!("estimator.window_m={window_m}");
            two_uav_run(
                "run-windows",
                &["--strict", "--set", &exchange, "--set", &window],
            )
        };
        let (none, covering) = (run("inf"), run("1000"));
        assert_eq!(none.1, covering.1, "{exchange}: timeseries.csv differs");
        assert_eq!(none.0, covering.0, "{exchange}: summary.json differs");
        // 25 m around each UAV in a 200 m region: `--strict` fails the run on a violation.
        let (small, _) = run("25");
        assert_eq!(small["violations"], 0, "{exchange}: {small}");
        assert_ne!(
            small["ua_final"], none.0["ua_final"],
            "{exchange}: no window?"
        );
    }
}

#[test]
fn killed_agents_leave_a_run_that_completes_with_guaranteed_survivors() {
    for exchange in ["sets", "measurements"] {
        killed_agents_leave_a_complete_run(exchange);
    }
}

/// The checks of `killed_agents_leave_a_run_that_completes_with_guaranteed_survivors` under
/// `comms.exchange = exchange`.
fn killed_agents_leave_a_complete_run(exchange: &str) {
    let t = TestRun::new("run-faults");
    let file = t.write("scenario.toml", &scenario(30.0, 3));
    let out_dir = t.dir.join("out");
    // Agent 0 killed at the start for good; agent 1 killed mid-run and restarted; agent 2
    // survives throughout.
    let args = [
        "--strict",
        "--fault",
        "kill:0@0.5",
        "--fault",
        "kill:1@6",
        "--fault",
        "restart:1@9",
        "--set",
        &format!("comms.exchange={exchange}"),
    ];
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &args)),
    );
    assert!(out.status.success(), "{exchange}: {}", stderr(&out));
    let s = summary(&out_dir);
    let steps = 60;
    assert_eq!(s["steps"], steps, "{s}");
    assert_eq!(s["violations"], 0, "{exchange}: {s}");
    let faults = s["faults"].as_array().expect("faults");
    assert_eq!(faults.len(), 3, "{s}");
    assert!(faults.iter().all(|f| f["effective"] == true), "{s}");
    let agents = s["agents"].as_array().expect("agents");
    assert_eq!(
        agents[2]["steps_processed"], steps,
        "the survivor missed steps: {s}"
    );
    assert!(
        agents[0]["steps_processed"].as_u64().expect("steps") <= 2,
        "{s}"
    );
    assert_eq!(agents[1]["restarts"], 1);
    // Agent 1 ran 0-6 s and 9-30 s: 13 + 42 steps, less the restart's start-up.
    let a1 = agents[1]["steps_processed"].as_u64().expect("steps");
    assert!(
        (30..=55).contains(&a1),
        "restarted agent processed {a1} steps: {s}"
    );
    // Every step was measured from at least the survivor's estimate.
    let csv = std::fs::read_to_string(out_dir.join("timeseries.csv")).expect("csv");
    for row in csv.lines().skip(1) {
        let estimates: u32 = row
            .split(',')
            .nth(3)
            .expect("estimates")
            .parse()
            .expect("count");
        assert!(estimates >= 1, "a step without estimates: {row}");
    }
}

#[test]
fn an_interrupted_run_stops_everything_and_leaves_nothing() {
    for (signal, name) in [(libc::SIGINT, "SIGINT"), (libc::SIGTERM, "SIGTERM")] {
        let t = TestRun::new("run-interrupt");
        // Far longer than the test: the run is stopped while it steps, however fast.
        let file = t.write("scenario.toml", &scenario(3600.0, 2));
        let out_dir = t.dir.join("out");
        let fleet = ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &[]));
        wait_until("the agents to start", Duration::from_secs(60), || {
            processes_mentioning(t.run.as_str()).len() >= 3
        });
        std::thread::sleep(Duration::from_secs(2));
        fleet.signal(signal);
        let out = finish(&t, fleet);
        assert_eq!(out.status.code(), Some(1), "{name}: {}", stderr(&out));
        assert!(stderr(&out).contains(name), "{name}: {}", stderr(&out));
        assert_eq!(summary(&out_dir)["interrupted"], true, "{name}");
    }
}

#[test]
fn a_killed_fleet_takes_its_children_along_and_the_next_run_cleans_up() {
    let first = TestRun::new("run-killed");
    // Far longer than the test: fleet is killed while the run steps, however fast.
    let file = first.write("scenario.toml", &scenario(3600.0, 2));
    let fleet = ChildGuard::spawn(&mut fleet_run(&first, &file, &first.dir.join("out"), &[]));
    wait_until("the agents to start", Duration::from_secs(60), || {
        processes_mentioning(first.run.as_str()).len() >= 3
    });
    std::thread::sleep(Duration::from_secs(1));
    fleet.signal(libc::SIGKILL);
    drop(fleet);
    wait_until(
        "the children to die with fleet",
        Duration::from_secs(10),
        || processes_mentioning(first.run.as_str()).is_empty(),
    );
    assert!(
        !first.ipc_files().is_empty(),
        "a killed run leaves files for the next to clean"
    );
    let next = TestRun::new("run-after-kill");
    let file = next.write("scenario.toml", &scenario(2.0, 2));
    let out = finish(
        &next,
        ChildGuard::spawn(&mut fleet_run(&next, &file, &next.dir.join("out"), &[])),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        first.ipc_files().is_empty(),
        "left: {:?}",
        first.ipc_files()
    );
}

#[test]
fn a_killed_world_server_ends_the_run_with_a_clear_message() {
    let t = TestRun::new("run-world-kill");
    // Far longer than the test: the world is killed while it steps, however fast.
    let file = t.write("scenario.toml", &scenario(3600.0, 2));
    let out_dir = t.dir.join("out");
    let fleet = ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &[]));
    let world = || {
        processes_mentioning(t.run.as_str())
            .into_iter()
            .find(|(_, cmd)| cmd.contains("world-server"))
    };
    wait_until("the world-server", Duration::from_secs(60), || {
        world().is_some()
    });
    std::thread::sleep(Duration::from_secs(2));
    let (pid, _) = world().expect("world-server running");
    // SAFETY: kill(2) on a pid read from /proc; no memory is involved.
    unsafe {
        libc::kill(pid as i32, libc::SIGKILL);
    }
    let out = finish(&t, fleet);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("world-server"), "{}", stderr(&out));
}

#[test]
fn bad_faults_and_arguments_exit_with_code_2_naming_the_flag() {
    let t = TestRun::new("run-bad-args");
    let file = t.write("scenario.toml", &scenario(10.0, 2));
    for (args, names) in [
        (vec!["--fault", "kill:5@1"], "--fault"),
        (vec!["--fault", "restart:0@1"], "--fault"),
        (vec!["--fault", "kill:0@99"], "--fault"),
        (vec!["--fault", "explode:0@1"], "--fault"),
        (vec!["--uavs", "0"], "uavs.count"),
        (vec!["--duration=-3"], "duration_s"),
        (vec!["--mode", "realtime", "--speedup", "0"], "--speedup"),
        (vec!["--variant", "best"], "--variant"),
        (vec!["--set", "guidance.planner=magic"], "guidance.planner"),
        (
            vec!["--variant", "setfleet", "--set", "guidance.beam_width=0"],
            "guidance.beam_width",
        ),
    ] {
        let out = finish(
            &t,
            ChildGuard::spawn(&mut fleet_run(&t, &file, &t.dir.join("out"), &args)),
        );
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(names), "{args:?}: {}", stderr(&out));
    }
}

#[test]
fn the_setfleet_variant_runs_and_is_recorded() {
    let t = TestRun::new("run-setfleet");
    let file = t.write("scenario.toml", &scenario(20.0, 2));
    let out_dir = t.dir.join("out");
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(
            &t,
            &file,
            &out_dir,
            &["--strict", "--variant", "setfleet"],
        )),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let s = summary(&out_dir);
    assert_eq!(s["variant"], "setfleet", "{s}");
    assert_eq!(s["violations"], 0, "{s}");
    for a in s["agents"].as_array().expect("agents") {
        // One decision per 1 s guidance period: 20 in 20 s (the first at step 0).
        assert!(a["decisions"].as_u64().expect("decisions") >= 19, "{a}");
        assert_eq!(a["token_timeouts"], 0, "{a}");
    }
    let resolved = std::fs::read_to_string(out_dir.join("scenario.toml")).expect("scenario");
    assert!(resolved.contains("planner = \"setfleet\""), "{resolved}");
    assert!(resolved.contains("guidance_period_s = 1.0"), "{resolved}");
}

/// The paper's sensor model end to end: the world measures depth along a random ray of each
/// pixel (eq. 5 leaves the ray unknown), cars come as close to the walls as the paper allows
/// (`r_s`), and the estimator's default rule keeps every car in its sets.
#[test]
fn random_depth_rays_keep_the_guarantee_end_to_end() {
    let t = TestRun::new("run-random-ray");
    let text = "seed = 3\nduration_s = 30.0\n\n\
                [region]\nhalf_extent_m = 100.0\nbuilding_fraction = 0.12\n\n\
                [targets]\ncount = 6\nbuilding_clearance_m = 3.0\n\n\
                [uavs]\ncount = 2\n\n\
                [camera]\nrows = 120\ncols = 160\ndepth_ray = \"random\"\n";
    let file = t.write("scenario.toml", text);
    let out_dir = t.dir.join("out");
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &["--strict"])),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let s = summary(&out_dir);
    assert_eq!(s["violations"], 0, "{s}");
    assert_eq!(s["steps"], 60, "{s}");
    let resolved = std::fs::read_to_string(out_dir.join("scenario.toml")).expect("scenario");
    for line in [
        "depth_ray = \"random\"",
        "depth_ray = \"any\"",
        "building_clearance_m = 3.0",
    ] {
        assert!(resolved.contains(line), "{line}: {resolved}");
    }
}

#[test]
fn run_and_sweep_help_list_and_explain_every_variant() {
    for command in ["run", "sweep"] {
        let out = Command::new(binary("fleet"))
            .args([command, "--help"])
            .output()
            .expect("fleet --help");
        assert!(out.status.success());
        let help = String::from_utf8_lossy(&out.stdout);
        assert!(help.contains("--variant"), "{command}: {help}");
        for (name, word) in [
            ("paper", "paper's MPC as written"),
            ("kappa0", "kappa = 0"),
            ("nomap", "without the map"),
            ("setfleet", "project's planner"),
        ] {
            assert!(
                help.contains(&format!("{name}:")) && help.contains(word),
                "{command} --help does not explain {name}: {help}"
            );
        }
    }
}
