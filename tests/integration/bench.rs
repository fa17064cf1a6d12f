//! `fleet bench ipc` runs every case in child processes (the Zenoh ones over TCP, TLS and QUIC),
//! writes a report with every headline key and leaves no iceoryx2 file behind.

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

/// The Zenoh cases and their headline keys' stem: `{stem}_p50_us`, `{stem}_p99_us`.
const ZENOH_CASES: [(&str, &str); 6] = [
    ("zenoh-frame-tcp", "zenoh_frame_tcp"),
    ("zenoh-frame-tls", "zenoh_frame_tls"),
    ("zenoh-frame-quic", "zenoh_frame_quic"),
    ("zenoh-estimate-tcp", "zenoh_estimate_tcp"),
    ("zenoh-estimate-tls", "zenoh_estimate_tls"),
    ("zenoh-estimate-quic", "zenoh_estimate_quic"),
];

/// Zenoh's rates, all positive numbers.
const ZENOH_RATE_KEYS: [&str; 6] = [
    "zenoh_frames_per_s_tcp",
    "zenoh_frames_per_s_tls",
    "zenoh_frames_per_s_quic",
    "zenoh_estimate_msgs_per_s_tcp",
    "zenoh_estimate_msgs_per_s_tls",
    "zenoh_estimate_msgs_per_s_quic",
];

fn positive(json: &serde_json::Value, key: &str) -> f64 {
    let v = json[key].as_f64().unwrap_or(f64::NAN);
    assert!(v.is_finite() && v > 0.0, "{key} = {:?}", json[key]);
    v
}

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
    ]
    .into_iter()
    .chain(ZENOH_CASES.map(|(case, _)| case))
    {
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
    for key in IPC_KEYS.into_iter().chain(ZENOH_RATE_KEYS) {
        positive(&json, key);
    }
    assert!(json["frame_p99_us"].as_f64() >= json["frame_p50_us"].as_f64());
    let cases = json["cases"]
        .as_array()
        .expect("the report lists its cases");
    assert_eq!(cases.len(), 5 + ZENOH_CASES.len());
    for (name, stem) in ZENOH_CASES {
        let p50 = positive(&json, &format!("{stem}_p50_us"));
        assert!(positive(&json, &format!("{stem}_p99_us")) >= p50, "{stem}");
        assert!(json[format!("{stem}_resent")].as_u64().is_some(), "{stem}");
        let case = cases
            .iter()
            .find(|c| c["name"] == name)
            .unwrap_or_else(|| panic!("no case {name}"));
        let bytes = case["metrics"]["msg_bytes"].as_f64().unwrap_or(0.0);
        // The frame is 864,000 bytes of pixels and its header; the estimate a few KB.
        let expected = if name.contains("frame") {
            864_000.0..866_000.0
        } else {
            100.0..1e6
        };
        assert!(expected.contains(&bytes), "{name}: {bytes} bytes");
        assert_eq!(case["metrics"]["p50_us"].as_f64(), Some(p50), "{name}");
    }
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
