//! `fleet sweep` end to end: a sweep, the same sweep split into shards and merged, the
//! same sweep with `--jobs 2` and the same sweep taken from `--cache` give the same table and
//! the same runs; an interrupted
//! `--jobs` sweep stops every run and leaves nothing; an axis sweep and a suite sweep compare
//! the values of a key and the variants on each scenario.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary, processes_mentioning, wait_until};

/// The small scenario of the run tests: 2 UAVs, 4 cars, a 200 m region.
const SCENARIO: &str = "seed = 3\nduration_s = 10.0\n\n[region]\nhalf_extent_m = 100.0\n\n\
                        [targets]\ncount = 4\n\n[uavs]\ncount = 2\n\n[camera]\nrows = 120\n\
                        cols = 160\n";

/// Two variants (their planners differ) on seeds 1 and 2 (as a range, which `--seeds 2`
/// means too), 4 s each.
const SWEEP: [&str; 6] = [
    "--seeds",
    "1..=2",
    "--variants",
    "paper,setfleet",
    "--duration",
    "4",
];
const RUNS: [(&str, u64); 4] = [("paper", 1), ("paper", 2), ("setfleet", 1), ("setfleet", 2)];

/// `fleet sweep` of the test scenario into `out` with the test's seeds and variants
/// ([`SWEEP`]) and `extra` arguments, run to its end; no process of it is left after.
fn sweep(t: &TestRun, out: &Path, extra: &[&str]) -> Output {
    sweep_with(t, out, &[SWEEP.as_slice(), extra].concat())
}

/// `fleet sweep` of the test scenario into `out` with `args`, run to its end; no process of it
/// is left after.
fn sweep_with(t: &TestRun, out: &Path, args: &[&str]) -> Output {
    sweep_of(t, &t.dir.join("scenario.toml"), out, args)
}

/// `fleet sweep --scenario scenario` (a file or a suite's directory) into `out` with `args`,
/// run to its end; no process of it is left after.
fn sweep_of(t: &TestRun, scenario: &Path, out: &Path, args: &[&str]) -> Output {
    let mut cmd = Command::new(binary("fleet"));
    cmd.arg("sweep")
        .arg("--scenario")
        .arg(scenario)
        .args(args)
        .arg("--out")
        .arg(out);
    let out = ChildGuard::spawn(&mut cmd)
        .wait_timeout(EXIT_TIMEOUT * 3)
        .unwrap_or_else(|| panic!("{cmd:?} did not end in time"));
    assert_nothing_left(t);
    out
}

/// No process started for the test's directory is left (each run's summary counts its
/// iceoryx2 files left, checked with the results).
fn assert_nothing_left(t: &TestRun) {
    let needle = t.dir.to_string_lossy().into_owned();
    wait_until(
        "the sweep's processes to exit",
        Duration::from_secs(10),
        || processes_mentioning(&needle).is_empty(),
    );
}

/// The sweep said it took `taken` of its `runs` runs from its `--cache`.
fn assert_taken(out: &Output, taken: usize, runs: usize) {
    let said = format!("{taken} of {runs} run(s) taken from the cache");
    assert!(stderr(out).contains(&said), "{}", stderr(out));
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// `value` without what depends on the wall clock: `wall_s`, `real_time_factor` (a key, or
/// a row of the table) and everything under `timing` and `resources` (CPU times and memory).
fn without_wall_clock(mut value: Value) -> Value {
    fn strip(v: &mut Value) {
        match v {
            Value::Object(map) => {
                for key in ["wall_s", "real_time_factor", "timing", "resources"] {
                    map.remove(key);
                }
                map.values_mut().for_each(strip);
            }
            Value::Array(items) => items.iter_mut().for_each(strip),
            _ => {}
        }
    }
    strip(&mut value);
    value
}

/// The sweep's table without wall-clock rows, and every run's summary (without wall-clock
/// fields) and time series.
fn results(dirs: &[PathBuf], table: &Path) -> (Value, Vec<(Value, String)>) {
    let runs = RUNS
        .iter()
        .map(|(variant, seed)| {
            let found: Vec<PathBuf> = dirs
                .iter()
                .map(|d| d.join(variant).join(format!("seed-{seed}")))
                .filter(|d| d.is_dir())
                .collect();
            assert_eq!(found.len(), 1, "{variant} seed {seed} in {found:?}");
            let csv = std::fs::read_to_string(found[0].join("timeseries.csv")).expect("csv");
            let s = json(&found[0].join("summary.json"));
            assert_eq!(s["timing"]["leftover_ipc_files"], 0, "{s}");
            let s = without_wall_clock(s);
            assert_eq!(s["violations"], 0, "{s}");
            assert_eq!(s["steps"], 8, "{s}");
            (s, csv)
        })
        .collect();
    (without_wall_clock(json(&table.join("table.json"))), runs)
}

#[test]
fn a_sweep_its_shards_merged_and_its_jobs_give_the_same_table() {
    let t = TestRun::new("sweep-split");
    t.write("scenario.toml", SCENARIO);

    let single = t.dir.join("single");
    let cache = t.dir.join("cache");
    let cache_arg = cache.to_str().expect("utf-8 path");
    let out = sweep(&t, &single, &["--cache", cache_arg]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_taken(&out, 0, 4);
    let whole = results(std::slice::from_ref(&single), &single);
    assert_eq!(whole.0["seeds"], serde_json::json!([1, 2]));
    assert_eq!(
        whole.0["variants"],
        serde_json::json!(["paper", "setfleet"])
    );
    assert_eq!(whole.0["failed_runs"], serde_json::json!([]));
    assert_paired(&whole.0, &single);

    // Five shards of four runs: run i in shard i mod 5, so shard 4 has none.
    let shards: Vec<PathBuf> = (0..5).map(|k| t.dir.join(format!("shard-{k}"))).collect();
    for (k, dir) in shards.iter().enumerate() {
        let out = sweep(&t, dir, &["--shard", &format!("{k}/5")]);
        assert!(out.status.success(), "shard {k}: {}", stderr(&out));
        assert_eq!(json(&dir.join("table.json"))["shard"], format!("{k}/5"));
        let runs: Vec<_> = RUNS
            .iter()
            .filter(|(v, s)| dir.join(v).join(format!("seed-{s}")).is_dir())
            .collect();
        assert_eq!(runs.len(), usize::from(k < 4), "shard {k}: {runs:?}");
    }
    let merged = t.dir.join("merged");
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["sweep", "--merge"])
        .args(&shards)
        .arg("--out")
        .arg(&merged);
    let out = tests::run_to_end(&mut cmd);
    assert!(out.status.success(), "{}", stderr(&out));
    let from_shards = results(&shards, &merged);
    assert_eq!(
        from_shards.1, whole.1,
        "the shards' runs differ from the sweep's"
    );
    assert_eq!(
        from_shards.0, whole.0,
        "the merged table differs from the sweep's"
    );

    let jobs = t.dir.join("jobs");
    let out = sweep(&t, &jobs, &["--jobs", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let parallel = results(std::slice::from_ref(&jobs), &jobs);
    assert_eq!(
        parallel.1, whole.1,
        "the --jobs 2 runs differ from the sweep's"
    );
    assert_eq!(
        parallel.0, whole.0,
        "the --jobs 2 table differs from the sweep's"
    );

    // The same sweep again runs nothing: every run comes from the cache, with its files.
    let again = t.dir.join("again");
    let out = sweep(&t, &again, &["--cache", cache_arg, "--jobs", "2"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_taken(&out, 4, 4);
    let cached = results(std::slice::from_ref(&again), &again);
    assert_eq!(cached, whole, "the cached sweep differs from the sweep");
    // An axis whose first value is the scenario's own runs only the other value.
    let axis = t.dir.join("axis");
    let args = [
        "--seeds",
        "1",
        "--variants",
        "paper",
        "--duration",
        "4",
        "--axis",
        "comms.loss=0,0.25",
        "--cache",
        cache_arg,
    ];
    let out = sweep_with(&t, &axis, &args);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_taken(&out, 1, 2);
}

/// The sweep's two variants compared seed by seed: on both seeds for the summary's values,
/// on none over the steady window (100-300 s), which 4 s runs do not reach.
fn assert_paired(table: &Value, dir: &Path) {
    assert_two_seed_comparisons(table, |p| {
        assert_eq!([&p["a"], &p["b"]], ["paper", "setfleet"], "{p}");
    });
    assert_eq!(table["steady_window_s"], serde_json::json!([100.0, 300.0]));
    let md = std::fs::read_to_string(dir.join("table.md")).expect("table.md");
    assert!(md.contains("Paired differences a − b"), "{md}");
    assert!(md.contains("| paper − setfleet | UA (pp) |"), "{md}");
    assert!(md.contains("(seeds 1..=2)"), "{md}");
}

#[test]
fn an_interrupted_jobs_sweep_stops_every_run_and_leaves_nothing() {
    let t = TestRun::new("sweep-interrupt");
    t.write("scenario.toml", SCENARIO);
    let out_dir = t.dir.join("out");
    let mut cmd = Command::new(binary("fleet"));
    cmd.arg("sweep")
        .arg("--scenario")
        .arg(t.dir.join("scenario.toml"))
        // Far longer than the test: the sweep is stopped while its runs step.
        .args(["--seeds", "2", "--variants", "paper", "--duration", "3600"])
        .args(["--jobs", "2", "--out"])
        .arg(&out_dir);
    let mut fleet = ChildGuard::spawn(&mut cmd);
    let needle = t.dir.to_string_lossy().into_owned();
    // Two runs: each a world-server and two agents.
    wait_until("both runs to start", Duration::from_secs(60), || {
        processes_mentioning(&needle).len() >= 6
    });
    std::thread::sleep(Duration::from_secs(2));
    fleet.signal(libc::SIGINT);
    let out = fleet
        .wait_timeout(EXIT_TIMEOUT)
        .expect("the interrupted sweep did not end in time");
    assert_nothing_left(&t);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    let table = json(&out_dir.join("table.json"));
    assert_eq!(
        table["failed_runs"],
        serde_json::json!(["paper/seed-1", "paper/seed-2"]),
        "{}",
        stderr(&out)
    );
    for seed in [1, 2] {
        let s = json(&out_dir.join(format!("paper/seed-{seed}/summary.json")));
        assert_eq!(s["interrupted"], true, "{s}");
        assert_eq!(s["timing"]["leftover_ipc_files"], 0, "{s}");
    }
}

#[test]
fn an_axis_sweep_compares_the_values_of_a_key() {
    let t = TestRun::new("sweep-axis");
    t.write("scenario.toml", SCENARIO);
    let out_dir = t.dir.join("out");
    let out = sweep_with(
        &t,
        &out_dir,
        &[
            "--seeds",
            "2",
            "--variants",
            "paper",
            "--duration",
            "4",
            "--axis",
            "comms.loss=0,0.5",
            "--jobs",
            "2",
        ],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    // Each value is a sweep directory of its own, whose runs have that value.
    for (value, loss) in [("0", 0.0), ("0.5", 0.5)] {
        let dir = out_dir.join(format!("comms.loss={value}"));
        let table = json(&dir.join("table.json"));
        assert_eq!(table["seeds"], serde_json::json!([1, 2]), "{table}");
        for seed in [1, 2] {
            let run = dir.join(format!("paper/seed-{seed}"));
            let s = json(&run.join("summary.json"));
            assert_eq!(s["violations"], 0, "{s}");
            let scenario = std::fs::read_to_string(run.join("scenario.toml")).expect("scenario");
            assert!(scenario.contains(&format!("loss = {loss:?}")), "{scenario}");
        }
    }
    let axis = json(&out_dir.join("axis.json"));
    assert_eq!(axis["key"], "comms.loss");
    assert_eq!(axis["values"], serde_json::json!(["0", "0.5"]));
    let lost = &axis["metrics"]["paper"];
    assert_eq!(lost[0]["estimates_lost_share"]["mean"], 0.0, "{axis}");
    assert!(
        lost[1]["estimates_lost_share"]["mean"].as_f64().unwrap() > 0.0,
        "{axis}"
    );
    assert_eq!(lost[1]["violations"]["mean"], 0.0, "{axis}");
    let md = std::fs::read_to_string(out_dir.join("axis.md")).expect("axis.md");
    assert!(
        md.contains("| metric | comms.loss = 0 | comms.loss = 0.5 |"),
        "{md}"
    );
    assert_axis_paired(&axis, &md);
    for picture in ["axis.png", "metrics.png"] {
        let bytes = std::fs::read(out_dir.join(picture)).expect(picture);
        assert!(bytes.starts_with(b"\x89PNG"), "{picture}");
    }
    // The comparison is rebuilt from the runs as written, by a merge.
    let merged = t.dir.join("merged");
    let mut cmd = Command::new(binary("fleet"));
    cmd.args(["sweep", "--merge"])
        .arg(&out_dir)
        .args(["--axis", "comms.loss=0,0.5", "--out"])
        .arg(&merged);
    let out = tests::run_to_end(&mut cmd);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        without_wall_clock(json(&merged.join("axis.json"))),
        without_wall_clock(axis)
    );
    assert!(merged.join("comms.loss=0.5/table.md").is_file());
    // The comparison of the values has nothing of the wall clock: the merge writes it alike.
    let merged_md = std::fs::read_to_string(merged.join("axis.md")).expect("axis.md");
    let paired = |md: &str| md.find("\nPaired differences").map(|i| md[i..].to_owned());
    assert!(paired(&md).is_some(), "{md}");
    assert_eq!(paired(&merged_md), paired(&md));
}

#[test]
fn a_suite_sweep_compares_the_variants_on_every_scenario() {
    let t = TestRun::new("sweep-suite");
    let suite = t.dir.join("suite");
    std::fs::create_dir_all(&suite).expect("suite directory");
    std::fs::write(
        suite.join("b-three-cars.toml"),
        SCENARIO.replace("count = 4", "count = 3"),
    )
    .expect("scenario b");
    std::fs::write(suite.join("a-small.toml"), SCENARIO).expect("scenario a");
    std::fs::write(suite.join("notes.md"), "not a scenario").expect("notes");
    let out_dir = t.dir.join("out");
    let out = sweep_of(
        &t,
        &suite,
        &out_dir,
        &[SWEEP.as_slice(), &["--jobs", "2"]].concat(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    // Each scenario is a sweep directory of its own, whose runs are of that scenario.
    for (name, cars) in [("a-small", 4), ("b-three-cars", 3)] {
        let dir = out_dir.join(name);
        let table = json(&dir.join("table.json"));
        assert_eq!(table["seeds"], serde_json::json!([1, 2]), "{table}");
        assert_two_seed_comparisons(&table, |p| {
            assert_eq!([&p["a"], &p["b"]], ["paper", "setfleet"], "{p}");
        });
        for (variant, seed) in RUNS {
            let s = json(&dir.join(format!("{variant}/seed-{seed}/summary.json")));
            assert_eq!(s["violations"], 0, "{s}");
            assert_eq!(s["targets"], cars, "{s}");
        }
    }
    let suite_json = json(&out_dir.join("suite.json"));
    let names: Vec<&str> = suite_json["scenarios"]
        .as_array()
        .expect("scenarios")
        .iter()
        .filter_map(|s| s["name"].as_str())
        .collect();
    assert_eq!(names, ["a-small", "b-three-cars"], "{suite_json}");
    let paired = suite_json["paired"].as_array().expect("paired");
    assert_eq!(paired.len(), 2 * 4 * 2, "{suite_json}");
    assert_eq!(paired[0]["scenario"], "a-small", "{suite_json}");
    assert_eq!(paired[8]["scenario"], "b-three-cars", "{suite_json}");
    let md = std::fs::read_to_string(out_dir.join("suite.md")).expect("suite.md");
    assert!(md.contains("| a-small | 2 | setfleet |"), "{md}");
    assert!(
        md.contains("| b-three-cars | paper − setfleet | UA (pp) |"),
        "{md}"
    );
    // A suite and an axis do not combine.
    let refused = sweep_of(
        &t,
        &suite,
        &t.dir.join("refused"),
        &["--seeds", "1", "--axis", "comms.loss=0,0.5"],
    );
    assert_eq!(refused.status.code(), Some(2), "{}", stderr(&refused));
    assert!(
        stderr(&refused).contains("--axis with a suite"),
        "{}",
        stderr(&refused)
    );
}

/// The axis's second value compared with its first seed by seed, for the one variant: on both
/// seeds for the summary's values, on none over the steady window (100-300 s), which 4 s runs
/// do not reach.
fn assert_axis_paired(axis: &Value, md: &str) {
    assert_two_seed_comparisons(axis, |p| {
        assert_eq!(
            [&p["variant"], &p["value"], &p["reference"]],
            ["paper", "0.5", "0"],
            "{p}"
        );
    });
    assert!(md.contains("Paired differences V − V₁"), "{md}");
    assert!(md.contains("| paper | 0.5 − 0 | UA (pp) |"), "{md}");
}

/// The `paired` entries of a sweep's table or axis made of two 4 s runs a side: every metric,
/// final then over the steady window (no pair there, as 4 s runs do not reach 100 s), each
/// entry naming its sides as `sides` checks, and UA's final difference over both seeds with
/// its mean inside its interval.
fn assert_two_seed_comparisons(json: &Value, sides: impl Fn(&Value)) {
    let paired = json["paired"].as_array().expect("paired");
    assert_eq!(paired.len(), 4 * 2, "{json}");
    let metrics: Vec<&str> = paired.iter().filter_map(|p| p["metric"].as_str()).collect();
    let each = ["ua", "oa", "target_set_area", "loc_error_m"];
    assert_eq!(metrics, each.map(|m| [m, m]).concat(), "{json}");
    for (i, p) in paired.iter().enumerate() {
        sides(p);
        let window = if i % 2 == 0 { "final" } else { "100-300 s" };
        assert_eq!(p["window"], window, "{p}");
        if window == "100-300 s" {
            assert_eq!(p["n"], 0, "{p}");
            assert_eq!(p["mean"], Value::Null, "{p}");
        }
    }
    let ua = &paired[0];
    assert_eq!(ua["n"], 2, "{ua}");
    let counts = ["a_better", "b_better", "ties"].map(|k| ua[k].as_u64().expect(k));
    assert_eq!(counts.iter().sum::<u64>(), 2, "{ua}");
    let ci = ua["ci95"].as_array().expect("ci95");
    let (lo, mean, hi) = (ci[0].as_f64(), ua["mean"].as_f64(), ci[1].as_f64());
    assert!(lo <= mean && mean <= hi, "{ua}");
}
