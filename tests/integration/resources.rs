//! `summary.json` `resources`: every process of a run, killed ones included, with its CPU
//! time, peak memory (its own when it reported it) and the phases of its time.

use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary};

/// A short 2-UAV run in a small region.
const SCENARIO: &str = "seed = 5\nduration_s = 10.0\n\n[region]\nhalf_extent_m = 100.0\n\n\
                        [targets]\ncount = 3\n\n[uavs]\ncount = 2\n\n[camera]\nrows = 90\n\
                        cols = 120\n";

#[test]
fn every_process_has_its_cpu_memory_and_phases_within_its_cpu() {
    let t = TestRun::new("resources");
    let file = t.write("scenario.toml", SCENARIO);
    let out_dir = t.dir.join("out");
    let mut cmd = std::process::Command::new(binary("fleet"));
    cmd.args(["run", "--run-id", t.run.as_str(), "--scenario"])
        .arg(&file)
        .arg("--out")
        .arg(&out_dir)
        .args(["--fault", "kill:1@3", "--fault", "restart:1@5"]);
    let out = ChildGuard::spawn(&mut cmd)
        .wait_timeout(EXIT_TIMEOUT)
        .expect("fleet run did not end in time");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(out_dir.join("summary.json")).expect("summary.json");
    let s: Value = serde_json::from_str(&text).expect("summary.json is JSON");
    let r = &s["resources"];
    let processes = r["processes"].as_array().expect("processes");
    let who: Vec<(String, Option<u64>, Option<u64>)> = processes
        .iter()
        .map(|p| {
            (
                p["role"].as_str().expect("role").to_owned(),
                p["uav"].as_u64(),
                p["incarnation"].as_u64(),
            )
        })
        .collect();
    let expected = [
        ("orchestrator", None, None),
        ("world", None, None),
        ("agent", Some(0), Some(1)),
        ("agent", Some(1), Some(1)),
        ("agent", Some(1), Some(2)),
    ];
    let expected: Vec<(String, Option<u64>, Option<u64>)> = expected
        .iter()
        .map(|(r, u, i)| ((*r).to_owned(), *u, *i))
        .collect();
    assert_eq!(who, expected, "{r}");
    let mut total = 0.0;
    for p in processes {
        let cpu = p["cpu_s"].as_f64().expect("cpu_s");
        total += cpu;
        assert!(cpu > 0.0, "no CPU time: {p}");
        assert!(p["peak_rss_mb"].as_f64().expect("peak_rss_mb") > 0.0, "{p}");
        let phases = p["phases"].as_object().expect("phases");
        let sum: f64 = phases.values().map(|v| v.as_f64().expect("cpu s")).sum();
        // The kernel's and the clocks' accounts differ by rounding only.
        assert!(
            sum <= cpu * 1.02 + 0.02,
            "phases {sum} s > CPU {cpu} s: {p}"
        );
        let has = |name: &str| phases.get(name).and_then(Value::as_f64).is_some();
        match (
            p["role"].as_str(),
            p["incarnation"].as_u64(),
            p["uav"].as_u64(),
        ) {
            (Some("orchestrator"), ..) => {
                assert!(has("observe"), "{p}");
                assert_eq!(p["peak_rss_source"], "rusage", "{p}");
            }
            (Some("world"), ..) => {
                assert!(has("render") && has("wait"), "{p}");
                // Its own peak, as it reported it, not the kernel's with the orchestrator's.
                assert_eq!(p["peak_rss_source"], "vmhwm", "{p}");
            }
            // Killed by the fault: it counts its CPU, printed no phases and no peak of its
            // own, so the kernel's peak stands in.
            (Some("agent"), Some(1), Some(1)) => {
                assert_eq!(p["end"], "signal 9", "{p}");
                assert!(phases.is_empty(), "{p}");
                assert_eq!(p["peak_rss_source"], "rusage", "{p}");
            }
            (Some("agent"), ..) => {
                assert_eq!(p["end"], "exit 0", "{p}");
                for name in ["estimate", "fuse", "plan", "publish", "wait_frame"] {
                    assert!(has(name), "no {name}: {p}");
                }
                assert_eq!(p["peak_rss_source"], "vmhwm", "{p}");
            }
            _ => panic!("unexpected process {p}"),
        }
    }
    let totals = &r["totals"];
    assert!((totals["cpu_s"].as_f64().expect("cpu_s") - total).abs() < 1e-6);
    assert!(totals["cpu_ms_per_uav_step"].as_f64().expect("per step") > 0.0);
    assert!(totals["wall_s_per_sim_s"].as_f64().expect("wall per sim") > 0.0);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("peak MB") && table.contains("agent 1 #2"),
        "{table}"
    );
}
