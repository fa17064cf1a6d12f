//! `fleet run --hosts N`: the processes spread over simulated hosts (own iceoryx2 domains)
//! joined by the Zenoh bridges; the same results as on one host, and faults across hosts.

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary, processes_mentioning, wait_until};

/// A small 4-UAV scenario (every host gets an agent with up to 4 hosts).
fn scenario(duration_s: f64) -> String {
    format!(
        "seed = 5\nduration_s = {duration_s}\n\n[region]\nhalf_extent_m = 100.0\n\n\
         [targets]\ncount = 4\n\n[uavs]\ncount = 4\n\n[camera]\nrows = 120\ncols = 160\n"
    )
}

fn fleet_run(t: &TestRun, scenario: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["run", "--strict", "--run-id", t.run.as_str(), "--scenario"])
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .args(extra);
    cmd
}

/// Runs to the end (bounded); checks that no process and no file of any host is left.
fn finish(t: &TestRun, mut fleet: ChildGuard) -> Output {
    let out = fleet
        .wait_timeout(EXIT_TIMEOUT)
        .expect("fleet run did not end in time");
    wait_until(
        "the run's processes to exit",
        Duration::from_secs(10),
        || processes_mentioning(t.run.as_str()).is_empty(),
    );
    assert!(t.ipc_files().is_empty(), "files left: {:?}", t.ipc_files());
    out
}

fn summary(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

/// The last line of a bridge's log: its report.
fn bridge_report(out: &Path, host: u16) -> Value {
    let log = std::fs::read_to_string(out.join(format!("logs/bridge-h{host}.log")))
        .expect("bridge log");
    let last = log.lines().last().expect("a report line");
    serde_json::from_str(last).unwrap_or_else(|e| panic!("bridge report {last:?}: {e}"))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn two_and_four_hosts_give_the_results_of_one_host_byte_for_byte() {
    let mut csvs = Vec::new();
    for hosts in ["1", "2", "4"] {
        let t = TestRun::new(&format!("hosts-{hosts}"));
        let file = t.write("scenario.toml", &scenario(10.0));
        let out_dir = t.dir.join("out");
        let out = finish(
            &t,
            ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &["--hosts", hosts])),
        );
        assert!(out.status.success(), "{hosts} hosts: {}", stderr(&out));
        let s = summary(&out_dir);
        assert_eq!(s["violations"], 0, "{s}");
        assert_eq!(s["hosts"].as_u64(), hosts.parse().ok(), "{s}");
        for a in s["agents"].as_array().expect("agents") {
            assert_eq!(a["steps_processed"], 20, "{hosts} hosts: {a}");
        }
        if hosts != "1" {
            let n: u16 = hosts.parse().expect("hosts");
            for host in 0..n {
                let r = bridge_report(&out_dir, host);
                assert_eq!(r["refused"], serde_json::json!({}), "host {host}: {r}");
                assert!(
                    r["received"]["estimate"]["messages"].as_u64() > Some(0),
                    "host {host}: {r}"
                );
                // Each agent host got its agents' frames over Zenoh.
                if host > 0 {
                    assert!(
                        r["received"]["frame"]["messages"].as_u64() >= Some(20),
                        "{r}"
                    );
                }
            }
        }
        csvs.push(std::fs::read_to_string(out_dir.join("timeseries.csv")).expect("csv"));
    }
    assert_eq!(csvs[0], csvs[1], "2 hosts: timeseries.csv differs from 1 host");
    assert_eq!(csvs[0], csvs[2], "4 hosts: timeseries.csv differs from 1 host");
}

#[test]
fn an_agent_killed_and_restarted_on_another_host_rejoins() {
    let t = TestRun::new("hosts-fault");
    let file = t.write("scenario.toml", &scenario(20.0));
    let out_dir = t.dir.join("out");
    // UAV 3 runs on host 1 of 2: its death and restart cross the bridge as liveliness.
    let args = [
        "--hosts",
        "2",
        "--fault",
        "kill:3@4",
        "--fault",
        "restart:3@8",
    ];
    let out = finish(
        &t,
        ChildGuard::spawn(&mut fleet_run(&t, &file, &out_dir, &args)),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let s = summary(&out_dir);
    assert_eq!(s["violations"], 0, "{s}");
    let agents = s["agents"].as_array().expect("agents");
    assert_eq!(agents[3]["restarts"], 1, "{s}");
    assert_eq!(agents[2]["steps_processed"], 40, "{s}");
    let processed = agents[3]["steps_processed"].as_u64().expect("steps");
    // Alive 0-4 s and 8-20 s, less the restart's start-up.
    assert!((28..40).contains(&processed), "{s}");
    // The world host saw the death through the bridge and made a new proxy at the restart.
    let r = bridge_report(&out_dir, 0);
    assert!(r["proxies_created"].as_u64() >= Some(3), "{r}");
}
