//! `fleet bench scale` end to end: a tiny scaling study (1 and 2 UAVs under both exchanges,
//! each over the whole region and with a 40 m window, 2 s each) writes a report with a row per
//! run and every field, the headline keys of each series, a decodable picture, sees no violation and leaves no process and no iceoryx2
//! file; bad flags exit with code 2 and name the flag.

use std::ffi::OsStr;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use protocol::ipc;
use protocol::service::RunId;
use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary, processes_mentioning, wait_until};

/// The 4-UAV reference of the test: a 200 m region with 4 cars and a small camera, so a
/// fleet of 1 has a 100 m region and 1 car, a fleet of 2 a 141 m region and 2 cars.
const SCENARIO: &str = "seed = 3\nduration_s = 10.0\n\n[region]\nhalf_extent_m = 100.0\n\n\
                        [targets]\ncount = 4\n\n[uavs]\ncount = 2\n\n[camera]\nrows = 36\n\
                        cols = 48\n";

/// What every row holds: positive numbers.
const POSITIVE: [&str; 13] = [
    "steps",
    "sim_s",
    "wall_s_per_sim_s",
    "real_time_factor",
    "cpu_ms_per_uav_step",
    "estimates_msgs_per_s",
    "estimates_bytes_per_s",
    "estimates_msgs_per_uav_s",
    "estimates_bytes_per_uav_s",
    "bytes_per_uav_s",
    "peak_rss_mb_world",
    "peak_rss_mb_agent_max",
    "peak_rss_mb_orchestrator",
];

/// `fleet bench scale` of the test scenario with `args`, run to its end.
fn scale(t: &TestRun, args: impl IntoIterator<Item = impl AsRef<OsStr>>) -> Output {
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["bench", "scale", "--scenario"])
        .arg(t.dir.join("scenario.toml"))
        .args(args);
    ChildGuard::spawn(&mut cmd)
        .wait_timeout(EXIT_TIMEOUT * 2)
        .unwrap_or_else(|| panic!("{cmd:?} did not end in time"))
}

fn json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The exchanges the test measures, in the order they run.
const EXCHANGES: [&str; 2] = ["sets", "measurements"];

/// The series the test measures, in the order they run: each exchange over the whole region,
/// then with windows of 40 m half-side (smaller than the 100 m and 141 m regions).
const SERIES: [(&str, &str, Option<f64>); 4] = [
    ("sets", "sets", None),
    ("sets_w40", "sets", Some(40.0)),
    ("measurements", "measurements", None),
    ("measurements_w40", "measurements", Some(40.0)),
];

#[test]
fn a_tiny_scale_bench_reports_every_size_under_both_exchanges_and_leaves_nothing() {
    let t = TestRun::new("scale");
    t.write("scenario.toml", SCENARIO);
    let out_dir = t.dir.join("out");
    let runs_dir = t.dir.join("runs");
    let out = scale(
        &t,
        [
            OsStr::new("--uavs"),
            OsStr::new("2,1"),
            OsStr::new("--exchange"),
            OsStr::new("sets,measurements"),
            OsStr::new("--window-m"),
            OsStr::new("inf,40"),
            OsStr::new("--duration"),
            OsStr::new("2"),
            OsStr::new("--out"),
            out_dir.as_os_str(),
            OsStr::new("--runs"),
            runs_dir.as_os_str(),
        ],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "fleet bench scale failed: {stderr}");
    // A line when each run is done: each series in turn, the sizes smallest first.
    for line in [
        "scale 1/8: sets, 1 UAVs, 1 cars",
        "scale 2/8: sets, 2 UAVs, 2 cars",
        "scale 3/8: sets, 40 m window, 1 UAVs, 1 cars",
        "scale 4/8: sets, 40 m window, 2 UAVs, 2 cars",
        "scale 5/8: measurements, 1 UAVs, 1 cars",
        "scale 8/8: measurements, 40 m window, 2 UAVs, 2 cars",
    ] {
        assert!(stderr.contains(line), "no {line:?} in {stderr}");
    }

    let report = json(&out_dir.join("scale.json"));
    assert_eq!(report["kind"], "scale");
    assert!(report["machine"]["cores"].as_u64().is_some_and(|c| c >= 1));
    assert!(
        report["command"]
            .as_str()
            .is_some_and(|c| c.contains("bench scale"))
    );
    assert_eq!(report["goal_real_time_factor"], 2.0);
    assert_eq!(report["goal_bytes_per_uav_ratio"], 1.5);
    assert_eq!(report["goal_cpu_per_uav_step_ratio"], 1.5);
    assert_eq!(report["goal_agent_peak_mb"], 60.0);
    assert_eq!(report["exchanges"], serde_json::json!(EXCHANGES));
    let keys: Vec<&str> = SERIES.iter().map(|s| s.0).collect();
    assert_eq!(report["series"], serde_json::json!(keys));
    // The headline keys of each series: null, as no run has 16 UAVs.
    for (series, ..) in SERIES {
        for key in [
            "real_time_factor_16",
            "bytes_per_uav_ratio_16",
            "cpu_per_uav_step_ratio_16",
            "agent_peak_mb_16",
        ] {
            let key = format!("{key}_{series}");
            assert_eq!(report.get(&key), Some(&Value::Null), "{key}: {report}");
        }
    }
    assert_eq!(report["violations"], 0);
    assert_eq!(report["failed_runs"], serde_json::json!([]));
    let cases = report["cases"].as_array().expect("cases");
    assert_eq!(cases.len(), 8, "{report}");
    let runs = SERIES
        .iter()
        .flat_map(|&s| [(s, 1, 1, 50.0), (s, 2, 2, 50.0 * 2f64.sqrt())]);
    for (case, ((series, exchange, window), uavs, cars, half)) in cases.iter().zip(runs) {
        assert_eq!(case["name"], format!("{series} uavs={uavs}"), "{case}");
        let p = &case["params"];
        assert_eq!(p["exchange"], exchange, "{case}");
        assert_eq!(p["window_m"], serde_json::json!(window), "{case}");
        assert_eq!(p["uavs"], uavs, "{case}");
        assert_eq!(p["cars"], cars, "{case}");
        assert_eq!(p["status"], "ok", "{case}");
        let side = p["region_side_m"].as_f64().unwrap_or(f64::NAN);
        assert!((side - 2.0 * half).abs() < 1e-6, "{case}");
        let m = &case["metrics"];
        for key in POSITIVE {
            let v = m[key].as_f64().unwrap_or(f64::NAN);
            assert!(
                v.is_finite() && v > 0.0,
                "{series} uavs={uavs}: {key} = {:?}",
                m[key]
            );
        }
        // 2 s of 0.5 s steps.
        assert_eq!(m["steps"], 4.0, "{case}");
        assert_eq!(m["violations"], 0.0, "{case}");
        assert_eq!(m["leftover_ipc_files"], 0.0, "{case}");
        let rtf = m["real_time_factor"].as_f64().unwrap_or(f64::NAN);
        let wall = m["wall_s_per_sim_s"].as_f64().unwrap_or(f64::NAN);
        assert!((rtf * wall - 1.0).abs() < 1e-9, "{case}");
        let per_uav = m["estimates_bytes_per_uav_s"].as_f64().unwrap_or(f64::NAN);
        let total = m["estimates_bytes_per_s"].as_f64().unwrap_or(f64::NAN);
        assert!((per_uav * f64::from(uavs) - total).abs() < 1e-6, "{case}");
        assert!(m["peak_rss_mb_agents_sum"].as_f64() >= m["peak_rss_mb_agent_max"].as_f64());
        // No 4-UAV row: no ratio.
        assert!(m.get("bytes_per_uav_ratio_to_4").is_none(), "{case}");
        assert!(m.get("cpu_per_uav_step_ratio_to_4").is_none(), "{case}");

        // Each run is a whole `fleet run` in its own directory, under its series.
        let run_dir = runs_dir.join(series).join(format!("uavs-{uavs}"));
        let summary = json(&run_dir.join("summary.json"));
        let scenario = std::fs::read_to_string(run_dir.join("scenario.toml"))
            .unwrap_or_else(|e| panic!("{}: {e}", run_dir.display()));
        assert!(
            scenario.contains(&format!("exchange = \"{exchange}\"")),
            "{series} uavs={uavs}: {scenario}"
        );
        let window_line = format!(
            "window_m = {}",
            window.map_or("inf".into(), |m| format!("{m:?}"))
        );
        assert!(
            scenario.contains(&window_line),
            "{series} uavs={uavs}: {scenario}"
        );
        assert_eq!(summary["uavs"], uavs);
        assert_eq!(summary["targets"], cars);
        assert_eq!(summary["mode"], "lockstep");
        assert_eq!(summary["timing"]["leftover_ipc_files"], 0);
        // The world's and the agents' memory is their own, not the bench process's.
        let processes = summary["resources"]["processes"]
            .as_array()
            .expect("processes");
        for p in processes.iter().filter(|p| p["role"] != "orchestrator") {
            assert_eq!(p["peak_rss_source"], "vmhwm", "{series} uavs={uavs}: {p}");
        }
        let run = summary["timing"]["run_id"].as_str().expect("run id");
        let run = RunId::new(run).expect("a valid run id");
        let left = ipc::run_files(&run).unwrap_or_default();
        assert!(
            left.is_empty(),
            "{series} uavs={uavs}: files left: {left:?}"
        );
    }

    let path = out_dir.join("scale.png");
    let file = std::fs::File::open(&path).unwrap_or_else(|e| panic!("scale.png: {e}"));
    let mut reader = png::Decoder::new(std::io::BufReader::new(file))
        .read_info()
        .unwrap_or_else(|e| panic!("scale.png is not a PNG: {e}"));
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("scale.png decodes");
    assert!(info.width >= 800 && info.height >= 600, "{info:?}");

    let needle = t.dir.to_string_lossy().into_owned();
    wait_until(
        "the bench's processes to exit",
        Duration::from_secs(10),
        || processes_mentioning(&needle).is_empty(),
    );
}

#[test]
fn bad_scale_flags_exit_2_naming_the_flag() {
    let t = TestRun::new("scale-args");
    t.write("scenario.toml", SCENARIO);
    let out_dir = t.dir.join("out");
    for (args, flag) in [
        (&["--uavs", ""][..], "--uavs"),
        (&["--uavs", "1,0"], "--uavs 0"),
        (
            &["--uavs", "1,65"],
            "--uavs 65: every fleet size must be 1 to 64",
        ),
        (&["--duration", "0"], "--duration 0"),
        (&["--duration=-1"], "--duration -1"),
        (&["--exchange", "bogus"], "--exchange"),
        (&["--exchange", "sets,bogus"], "--exchange"),
        (&["--window-m=-5"], "--window-m"),
        (
            &["--window-m", "auto,none"],
            "a window is `inf`, `auto` or a positive number",
        ),
    ] {
        let with_out = args
            .iter()
            .map(OsStr::new)
            .chain([OsStr::new("--out"), out_dir.as_os_str()]);
        let out = scale(&t, with_out);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(flag), "{args:?}: {stderr}");
    }
    assert!(!out_dir.exists(), "nothing runs on bad arguments");
}
