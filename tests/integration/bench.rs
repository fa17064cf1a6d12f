//! `fleet bench ipc` runs every case in child processes, writes a report with every headline
//! key and leaves no iceoryx2 file behind.

use std::process::Command;

use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary, small_scenario_toml};

/// The keys docs/design.md §7 names for `fleet bench ipc`, all positive numbers.
const IPC_KEYS: [&str; 8] = [
    "frame_p50_us",
    "frame_p99_us",
    "frames_per_s_1sub",
    "frames_per_s_4sub",
    "baseline_frame_p50_us",
    "speedup",
    "estimate_msgs_per_s",
    "token_round_us",
];

#[test]
fn bench_ipc_reports_every_key_and_cleans_up() {
    let t = TestRun::new("bench-ipc");
    let scenario = t.write("scenario.toml", &small_scenario_toml(10.0));
    let out_file = t.dir.join("ipc.json");
    let mut fleet = ChildGuard::spawn(
        Command::new(binary("fleet"))
            .args([
                "bench",
                "ipc",
                "--quick",
                "--iterations",
                "20",
                "--scenario",
            ])
            .arg(&scenario)
            .arg("--out")
            .arg(&out_file),
    );
    let pid = fleet.id();
    let out = fleet
        .wait_timeout(EXIT_TIMEOUT)
        .unwrap_or_else(|| panic!("fleet bench ipc did not end within {EXIT_TIMEOUT:?}"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "fleet bench ipc failed: {stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    for case in [
        "iox-1sub",
        "iox-4sub",
        "socket-1sub",
        "estimates",
        "token-round",
    ] {
        assert!(stdout.contains(case), "the table lacks {case}: {stdout}");
    }
    let text = std::fs::read_to_string(&out_file).expect("the report was written");
    let json: serde_json::Value = serde_json::from_str(&text).expect("the report is JSON");
    assert_eq!(json["kind"], "ipc");
    assert!(json["machine"]["cores"].as_u64().is_some_and(|c| c >= 1));
    assert!(
        json["command"]
            .as_str()
            .is_some_and(|c| c.contains("bench ipc"))
    );
    for key in IPC_KEYS {
        let v = json[key].as_f64().unwrap_or(f64::NAN);
        assert!(v.is_finite() && v > 0.0, "{key} = {:?}", json[key]);
    }
    assert!(json["frame_p99_us"].as_f64() >= json["frame_p50_us"].as_f64());
    assert_eq!(json["cases"].as_array().map(Vec::len), Some(5));
    let prefix = format!("iox2_sf_bench-ipc-{pid}-");
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with(&prefix))
                .collect()
        })
        .unwrap_or_default();
    assert!(left.is_empty(), "files left behind: {left:?}");
}
