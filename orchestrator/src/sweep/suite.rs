//! `fleet sweep --scenario DIR`: the same sweep on every scenario of a suite (every `*.toml`
//! file of `DIR`, in the order of their names), and the variants compared scenario by
//! scenario.
//!
//! The runs of scenario `NAME.toml` go under `NAME/<variant>/seed-<n>/`, so each `NAME/`
//! directory is a sweep directory of its own, with its `table.json`, `table.md` and
//! `metrics.png` (and `fleet sweep --merge` reads it like any sweep). Beside them the sweep
//! writes `suite.json` and `suite.md`:
//!
//! - per scenario and variant, UA (final and over the steady window) and the localisation
//!   error (mean over the run), mean ± sample standard deviation over the seeds;
//! - per scenario, every two variants compared seed by seed as `table.md` compares them
//!   ([`super::paired`]): the mean difference `a − b` on UA, OA, target-set area and
//!   localisation error, its 95 % confidence interval and who was lower how often.
//!
//! `fleet sweep --merge A B --out C` of suite sweeps merges them scenario by scenario
//! ([`merge`]), so a suite swept in parts (seeds, variants or scenarios at a time) makes one
//! `suite.md`.
//!
//! The project keeps a held-out suite, `scenarios/suite/`, and scenarios for tuning,
//! `scenarios/tuning/` (`scenarios/README.md` says what each scenario stresses and which
//! choices were made on which): `fleet sweep --scenario scenarios/suite --variants paper,setfleet
//! --seeds 10 --jobs 2`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use serde::Serialize;

use super::metrics::{Metric, metric};
use super::paired::{self, Comparison, Paired, PairedMetric, Sides};
use super::table::{Cell, Table, format_cell};
use crate::outcome::Outcome;
use fleet_process::usage::UsageError;
use protocol::variant::Variant;

/// Most scenarios a suite holds.
pub const MAX_SUITE_SCENARIOS: usize = 64;

/// The scenarios of a suite directory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Suite {
    /// Each scenario's name (its file's stem) and file, in the order of the names.
    pub scenarios: Vec<(String, PathBuf)>,
}

impl Suite {
    /// The `*.toml` files of `dir`, by name: at least one, at most [`MAX_SUITE_SCENARIOS`].
    pub fn read(dir: &Path) -> Result<Suite, UsageError> {
        let fail = |why: String| UsageError(format!("--scenario {}: {why}", dir.display()));
        let entries = std::fs::read_dir(dir).map_err(|e| fail(format!("cannot list: {e}")))?;
        let mut scenarios = Vec::new();
        for entry in entries {
            let path = entry.map_err(|e| fail(format!("cannot list: {e}")))?.path();
            if path.extension().is_none_or(|e| e != "toml") || !path.is_file() {
                continue;
            }
            let name = path
                .file_stem()
                .and_then(|s| s.to_str())
                .filter(|s| {
                    s.chars()
                        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
                })
                .ok_or_else(|| {
                    fail(format!(
                        "{}: a scenario's file name must be letters, digits, - _ and .",
                        path.display()
                    ))
                })?
                .to_owned();
            scenarios.push((name, path));
        }
        scenarios.sort();
        if scenarios.is_empty() {
            return Err(fail("no *.toml scenario in the directory".into()));
        }
        if scenarios.len() > MAX_SUITE_SCENARIOS {
            return Err(fail(format!(
                "at most {MAX_SUITE_SCENARIOS} scenarios in a suite"
            )));
        }
        Ok(Suite { scenarios })
    }
}

/// Whether `dir` holds a suite's sweep (its `suite.json`).
pub fn is_suite_sweep(dir: &Path) -> bool {
    dir.join("suite.json").is_file()
}

/// `fleet sweep --merge` of suite sweeps (every source holds `suite.json`): each scenario's
/// runs, from every source that has them, merged under `out/NAME/` as a plain merge merges
/// one sweep, then `suite.md` and `suite.json` over the scenarios found, by name. Suites swept
/// in parts (other seeds, other variants, one scenario at a time) thus make one suite table.
pub fn merge(sources: &[PathBuf], out: &Path) -> anyhow::Result<Outcome> {
    let mut names = std::collections::BTreeSet::new();
    for dir in sources {
        for entry in
            std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))?
        {
            let path = entry?.path();
            if path.join("table.json").is_file()
                && let Some(name) = path.file_name().and_then(|n| n.to_str())
            {
                names.insert(name.to_owned());
            }
        }
    }
    anyhow::ensure!(
        !names.is_empty(),
        "no scenario's sweep (NAME/table.json) under the merged suites"
    );
    let mut scenarios = Vec::with_capacity(names.len());
    let mut tables = Vec::with_capacity(names.len());
    for name in names {
        let parts: Vec<PathBuf> = sources
            .iter()
            .map(|dir| dir.join(&name))
            .filter(|dir| dir.is_dir())
            .collect();
        tables.push(super::collect::merge_into(&parts, &out.join(&name))?);
        let file = sources
            .iter()
            .find_map(|dir| scenario_file(dir, &name))
            .unwrap_or_else(|| parts[0].clone());
        scenarios.push((name, file));
    }
    write(&Suite { scenarios }, &tables, out)?;
    Ok(if tables.iter().all(|t| t.failed_runs.is_empty()) {
        Outcome::Success
    } else {
        Outcome::Failed
    })
}

/// The file of scenario `name` as the suite sweep in `dir` recorded it in its `suite.json`.
fn scenario_file(dir: &Path, name: &str) -> Option<PathBuf> {
    let text = std::fs::read_to_string(dir.join("suite.json")).ok()?;
    let suite: serde_json::Value = serde_json::from_str(&text).ok()?;
    let scenario = suite["scenarios"]
        .as_array()?
        .iter()
        .find(|s| s["name"] == name)?;
    scenario["file"].as_str().map(PathBuf::from)
}

/// One scenario's variants in `suite.json`.
#[derive(Debug, Serialize)]
struct ScenarioResults<'a> {
    /// The scenario's name.
    name: &'a str,
    /// Its file.
    file: String,
    /// The seeds its runs had.
    seeds: &'a [u64],
    /// Per variant, the suite's rows (`ua_final`, `ua_window`, `loc_error_mean_m`).
    variants: Vec<(Variant, Vec<(&'static str, &'a Cell)>)>,
    /// Runs that failed or were interrupted.
    failed_runs: &'a [String],
}

/// Two variants compared on one scenario: an object of `paired` in `suite.json`.
#[derive(Debug, Serialize)]
struct ScenarioPaired<'a> {
    /// The scenario's name.
    scenario: &'a str,
    /// The comparison.
    #[serde(flatten)]
    paired: &'a Paired,
}

impl Comparison for ScenarioPaired<'_> {
    fn sides(&self) -> String {
        format!("{} | {}", self.scenario, self.paired.sides())
    }

    fn compared(&self) -> &PairedMetric {
        &self.paired.compared
    }
}

/// The columns of the suite's first table: a metric of the scenarios' tables and its heading,
/// shorter than its label.
const SUITE_COLUMNS: [(&Metric, &str); 3] = [
    (metric("ua_final"), "UA final (%)"),
    (metric("ua_window"), "UA 100-300 s (%)"),
    (metric("loc_error_mean_m"), "loc. error (m)"),
];

/// Writes `suite.json` and `suite.md` into `out` from each scenario's table (in the suite's
/// order) and prints `suite.md`.
pub fn write(suite: &Suite, tables: &[Table], out: &Path) -> anyhow::Result<()> {
    let results: Vec<ScenarioResults<'_>> = suite
        .scenarios
        .iter()
        .zip(tables)
        .map(|((name, file), table)| ScenarioResults {
            name,
            file: file.display().to_string(),
            seeds: &table.seeds,
            variants: table
                .variants
                .iter()
                .map(|v| {
                    let cells = SUITE_COLUMNS
                        .iter()
                        .filter_map(|(metric, _)| {
                            let cell = table.metrics.get(v.name())?.get(metric.key)?;
                            Some((metric.key, cell))
                        })
                        .collect();
                    (*v, cells)
                })
                .collect(),
            failed_runs: &table.failed_runs,
        })
        .collect();
    let paired: Vec<ScenarioPaired<'_>> = suite
        .scenarios
        .iter()
        .zip(tables)
        .flat_map(|((name, _), table)| {
            table.paired.iter().map(move |paired| ScenarioPaired {
                scenario: name,
                paired,
            })
        })
        .collect();
    #[derive(Serialize)]
    struct SuiteJson<'a> {
        scenarios: &'a [ScenarioResults<'a>],
        paired: &'a [ScenarioPaired<'a>],
    }
    let json = serde_json::to_string_pretty(&SuiteJson {
        scenarios: &results,
        paired: &paired,
    })? + "\n";
    std::fs::write(out.join("suite.json"), json).context("cannot write suite.json")?;
    let md = to_markdown(&results, &paired);
    std::fs::write(out.join("suite.md"), &md).context("cannot write suite.md")?;
    println!("{md}\nresults in {}", out.display());
    Ok(())
}

/// `suite.md`: the variants per scenario, then their paired differences per scenario.
fn to_markdown(results: &[ScenarioResults<'_>], paired: &[ScenarioPaired<'_>]) -> String {
    let mut md = String::from(
        "Every scenario of the suite: mean ± standard deviation over the seeds, per variant.\n\n",
    );
    let _ = write!(md, "| scenario | seeds | variant |");
    for (_, head) in SUITE_COLUMNS {
        let _ = write!(md, " {head} |");
    }
    let _ = writeln!(
        md,
        "\n|---|---:|---|{}",
        "---:|".repeat(SUITE_COLUMNS.len())
    );
    for scenario in results {
        for (variant, cells) in &scenario.variants {
            let _ = write!(
                md,
                "| {} | {} | {} |",
                scenario.name,
                scenario.seeds.len(),
                variant.name()
            );
            for (metric, _) in SUITE_COLUMNS {
                let cell = cells
                    .iter()
                    .find(|(k, _)| *k == metric.key)
                    .map(|(_, c)| *c);
                let text = cell.map_or_else(|| "-".into(), |c| format_cell(c, metric.scale));
                let _ = write!(md, " {text} |");
            }
            md.push('\n');
        }
    }
    let failed: Vec<String> = results
        .iter()
        .flat_map(|s| s.failed_runs.iter().map(move |r| format!("{}/{r}", s.name)))
        .collect();
    if !failed.is_empty() {
        let _ = writeln!(md, "\nFailed or interrupted runs: {}.", failed.join(", "));
    }
    let sides = Sides {
        title: "Paired differences a − b per scenario",
        a: "a",
        b: "b",
        heads: "scenario | a − b",
    };
    paired::write_section(&sides, paired, &mut md);
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_suite_is_the_toml_files_of_a_directory_by_name() {
        let root = std::env::temp_dir().join(format!("setfleet-suite-{}", std::process::id()));
        let (dir, empty) = (root.join("suite"), root.join("empty"));
        std::fs::create_dir_all(&empty).unwrap();
        std::fs::create_dir_all(dir.join("c.toml")).unwrap();
        for name in ["b.toml", "a.toml", "notes.md"] {
            std::fs::write(dir.join(name), "").unwrap();
        }
        let suite = Suite::read(&dir).unwrap();
        let names: Vec<&str> = suite.scenarios.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["a", "b"]);
        let e = Suite::read(&empty).unwrap_err();
        assert!(e.0.contains("no *.toml scenario"), "{e}");
        assert!(Suite::read(&root.join("missing")).is_err());
        std::fs::write(dir.join("a b.toml"), "").unwrap();
        let e = Suite::read(&dir).unwrap_err();
        assert!(e.0.contains("file name"), "{e}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    /// Suites swept in parts (one variant each, one with a scenario the other lacks) merge
    /// into one suite table, scenario by scenario.
    #[test]
    fn suites_swept_in_parts_merge_scenario_by_scenario() {
        use super::super::collect::tests::fake_run;
        fleet_observe::pictures::register_fonts().unwrap();
        let root =
            std::env::temp_dir().join(format!("setfleet-suite-merge-{}", std::process::id()));
        let (a, b, out) = (root.join("a"), root.join("b"), root.join("out"));
        for (dir, variant, ua) in [(&a, Variant::Paper, 0.5), (&b, Variant::Setfleet, 0.3)] {
            for seed in [1, 2] {
                fake_run(&dir.join("city"), variant, seed, ua);
            }
            std::fs::write(dir.join("city/table.json"), "{}").unwrap();
            std::fs::write(dir.join("suite.json"), "{}").unwrap();
        }
        let recorded = r#"{"scenarios": [{"name": "city", "file": "suite/city.toml"}]}"#;
        std::fs::write(a.join("suite.json"), recorded).unwrap();
        fake_run(&a.join("suburb"), Variant::Paper, 1, 0.7);
        std::fs::write(a.join("suburb/table.json"), "{}").unwrap();
        assert!(is_suite_sweep(&a) && !is_suite_sweep(&a.join("city")));
        assert_eq!(merge(&[a, b], &out).unwrap(), Outcome::Success);
        let suite: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("suite.json")).unwrap())
                .unwrap();
        let names: Vec<&str> = suite["scenarios"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|s| s["name"].as_str())
            .collect();
        assert_eq!(names, ["city", "suburb"]);
        // The file a source recorded, else the scenario's directory.
        assert_eq!(suite["scenarios"][0]["file"], "suite/city.toml");
        let suburb = suite["scenarios"][1]["file"].as_str().unwrap();
        assert!(suburb.ends_with("a/suburb"), "{suburb}");
        let city: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("city/table.json")).unwrap())
                .unwrap();
        assert_eq!(city["variants"], serde_json::json!(["paper", "setfleet"]));
        assert_eq!(city["metrics"]["setfleet"]["ua_final"]["mean"], 0.3);
        let paired = suite["paired"].as_array().unwrap();
        // paper − setfleet on the city only (the suburb has one variant): 4 metrics, 2 windows.
        assert_eq!(paired.len(), 8, "{suite}");
        assert!(paired.iter().all(|p| p["scenario"] == "city"), "{suite}");
        let ua = paired[0]["mean"].as_f64().unwrap();
        assert!((ua - 0.2).abs() < 1e-12, "{suite}");
        std::fs::remove_dir_all(&root).unwrap();
    }

    /// `suite.md` and the rows of `suite.json` as a suite of one scenario writes them: the
    /// columns, their headings and their formats, byte for byte.
    #[test]
    fn the_suite_table_text_is_pinned() {
        use super::super::metrics::METRICS;
        let run = |ua: f64, window: Option<f64>, error: f64| {
            let mut values = vec![None; METRICS.len()];
            for (key, value) in [
                ("ua_final", Some(ua)),
                ("ua_window", window),
                ("loc_error_mean_m", Some(error)),
            ] {
                values[METRICS.iter().position(|m| m.key == key).unwrap()] = value;
            }
            values
        };
        let results = vec![
            (
                Variant::Paper,
                vec![run(0.30, None, 3.5), run(0.20, None, 4.5)],
            ),
            (
                Variant::Setfleet,
                vec![run(0.10, Some(0.2), 12.0), run(0.10, Some(0.4), 14.0)],
            ),
        ];
        let table = Table::build(vec![1, 2], &results, vec!["paper/seed-3".into()]);
        let suite = Suite {
            scenarios: vec![("city".into(), PathBuf::from("suite/city.toml"))],
        };
        let dir = std::env::temp_dir().join(format!("setfleet-suite-text-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write(&suite, &[table], &dir).unwrap();
        let md = std::fs::read_to_string(dir.join("suite.md")).unwrap();
        let expected = "\
Every scenario of the suite: mean ± standard deviation over the seeds, per variant.

| scenario | seeds | variant | UA final (%) | UA 100-300 s (%) | loc. error (m) |
|---|---:|---|---:|---:|---:|
| city | 2 | paper | 25.00 ± 7.07 | - | 4.00 ± 0.71 |
| city | 2 | setfleet | 10.00 ± 0.00 | 30.00 ± 14.14 | 13.0 ± 1.4 |

Failed or interrupted runs: city/paper/seed-3.

Paired differences a − b per scenario, seed by seed on the seeds both ran: mean Δ [95 % \
confidence interval, Student's t], and on how many seeds a was lower / b was lower / they tied. \
Lower is better for these four metrics, so Δ < 0 favours a; a CI that excludes 0 means the \
difference is measurable on these seeds. Final: the row above (UA and OA at the end, area and \
error over the whole run); 100-300 s: the mean over that window. Fractions in percentage points \
(pp).

| scenario | a − b | metric | Δ final [95 % CI] | a / b lower, ties | Δ 100-300 s [95 % CI] | a / b lower, ties |
|---|---|---|---:|---:|---:|---:|
| city | paper − setfleet | UA (pp) | 15.00 [-48.53, 78.53] | 0 / 2, 0 | - | - |
| city | paper − setfleet | OA (pp) | - | - | - | - |
| city | paper − setfleet | target-set area (pp) | - | - | - | - |
| city | paper − setfleet | localisation error (m) | -9.00 [-15.35, -2.65] | 2 / 0, 0 | - | - |
";
        assert_eq!(md, expected);
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("suite.json")).unwrap())
                .unwrap();
        let keys: Vec<&str> = json["scenarios"][0]["variants"][1][1]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|cell| cell[0].as_str())
            .collect();
        assert_eq!(keys, ["ua_final", "ua_window", "loc_error_mean_m"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The project's suites (held out and for tuning) read, share no scenario, and every
    /// scenario of them loads with every variant.
    #[test]
    fn the_projects_suites_load_with_every_variant() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let held_out = Suite::read(&root.join("suite")).unwrap();
        let tuning = Suite::read(&root.join("tuning")).unwrap();
        assert!(held_out.scenarios.len() >= 5, "{held_out:?}");
        assert!(tuning.scenarios.len() >= 2, "{tuning:?}");
        for (name, file) in held_out.scenarios.iter().chain(&tuning.scenarios) {
            for variant in Variant::ALL {
                let overrides = variant.with_user_overrides(&[]);
                protocol::scenario::Scenario::load(Some(file), &overrides)
                    .unwrap_or_else(|e| panic!("{name} with {}: {e}", variant.name()));
            }
        }
        for (name, _) in &tuning.scenarios {
            assert!(
                held_out.scenarios.iter().all(|(other, _)| other != name),
                "{name} is in both suites"
            );
        }
    }
}
