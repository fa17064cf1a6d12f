//! `fleet sweep`: every variant on seeds 1..=N, one full run each (as separate processes,
//! like `fleet run`), then the paper's Table I layout: one row per final metric, one column
//! per variant, mean ± sample standard deviation over the seeds.
//!
//! Writes into `--out`: each run's results under `<variant>/seed-<n>/`, `table.json`,
//! `table.md` and `metrics.png` (UA and OA over time per variant, mean ± 1 sd).
//!
//! `fleet sweep --merge DIR... --out DIR` builds the same table and picture from the runs of
//! several sweeps (say, one per variant, or one per machine), read back from their
//! `summary.json` and `timeseries.csv`: every run depends only on its variant and seed, so
//! the merged table is the one a single sweep of all of them would write. A run found twice
//! is an error.
//!
//! The variants are those of [`crate::variant`]: `nomap`, `kappa0`, `paper` (the paper's
//! Table I columns) and `setfleet` (the project's planner).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Args;
use serde::Serialize;

use crate::Outcome;
use crate::observe::StepMetrics;
use crate::results::curves::{draw_sweep, mean_sd};
use crate::results::summary::Summary;
use crate::results::timeseries;
use crate::run::config::{RunConfig, new_run_id};
use crate::run::{execute, outcome, runtime, write_results};
use crate::usage::{ScenarioArgs, UsageError};
pub use crate::variant::Variant;
use world_server::server::StepMode;

/// `fleet sweep`.
#[derive(Debug, Clone, Args)]
pub struct SweepArgs {
    /// The scenario (its seed is replaced by 1..=N).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Number of seeds: runs use seeds 1..=N.
    #[arg(long, required_unless_present = "merge")]
    pub seeds: Option<u32>,
    /// Variants to run, comma-separated, in the table's column order (each is a named set of
    /// scenario settings; `--set` overrides apply after them).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = Variant::ALL.to_vec())]
    pub variants: Vec<Variant>,
    /// Overrides the scenario's `duration_s`, seconds of simulated time.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Output directory (default: `runs/sweep-<UTC timestamp>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Runs nothing: builds the table and picture from the runs of these sweep directories.
    #[arg(long, num_args = 1.., value_name = "DIR", conflicts_with_all = ["seeds", "duration", "variants", "scenario", "overrides"])]
    pub merge: Vec<PathBuf>,
}

/// A validated `fleet sweep --merge`.
#[derive(Debug, Clone)]
pub struct MergeConfig {
    /// The sweep directories read.
    pub sources: Vec<PathBuf>,
    /// Output directory.
    pub out: PathBuf,
}

/// A validated `fleet sweep`: one run configuration per (variant, seed).
#[derive(Debug, Clone)]
pub struct SweepConfig {
    /// Runs in order: variant-major.
    pub runs: Vec<(Variant, u64, RunConfig)>,
    /// Variants in column order.
    pub variants: Vec<Variant>,
    /// Output directory.
    pub out: PathBuf,
}

impl SweepArgs {
    /// Checks the counts and every variant's scenario.
    pub fn validate(&self) -> Result<SweepConfig, UsageError> {
        let seeds = self
            .seeds
            .ok_or_else(|| UsageError("--seeds: give the number of seeds".into()))?;
        if seeds == 0 || seeds > 1000 {
            return Err(UsageError(format!("--seeds {seeds}: must be 1 to 1000")));
        }
        let mut variants = self.variants.clone();
        variants.dedup();
        if variants.is_empty() {
            return Err(UsageError("--variants: name at least one variant".into()));
        }
        let out = self
            .out
            .clone()
            .unwrap_or_else(|| crate::run::config::default_out_dir("sweep-"));
        let progress_bar = std::io::IsTerminal::is_terminal(&std::io::stderr());
        let mut runs = Vec::new();
        for &variant in &variants {
            for seed in 1..=u64::from(seeds) {
                let mut overrides = variant.with_user_overrides(&self.scenario.overrides);
                overrides.push(format!("seed={seed}"));
                if let Some(d) = self.duration {
                    overrides.push(format!("duration_s={d:?}"));
                }
                let scenario = ScenarioArgs {
                    scenario: self.scenario.scenario.clone(),
                    overrides,
                }
                .load()?;
                let sequence = runs.len() as u32;
                runs.push((
                    variant,
                    seed,
                    RunConfig {
                        scenario,
                        mode: StepMode::Lockstep,
                        faults: Vec::new(),
                        out: out.join(variant.name()).join(format!("seed-{seed}")),
                        strict: false,
                        run_id: new_run_id(sequence),
                        progress_bar,
                        variant,
                        chaos_seed: None,
                    },
                ));
            }
        }
        Ok(SweepConfig {
            runs,
            variants,
            out,
        })
    }
}

impl SweepArgs {
    /// The merge this command asks for, `None` when it asks for runs.
    pub fn merge_config(&self) -> Option<MergeConfig> {
        (!self.merge.is_empty()).then(|| MergeConfig {
            sources: self.merge.clone(),
            out: self
                .out
                .clone()
                .unwrap_or_else(|| crate::run::config::default_out_dir("sweep-")),
        })
    }
}

/// One metric of the table: mean, standard deviation and the values per seed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cell {
    /// Mean over the runs that have the metric.
    pub mean: Option<f64>,
    /// Sample standard deviation.
    pub sd: Option<f64>,
    /// The value of each run, by seed (`null` where the run has none).
    pub values: Vec<Option<f64>>,
}

impl Cell {
    fn of(values: Vec<Option<f64>>) -> Cell {
        let present: Vec<f64> = values.iter().flatten().copied().collect();
        let stats = mean_sd(&present);
        Cell {
            mean: stats.map(|s| s.0),
            sd: stats.map(|s| s.1),
            values,
        }
    }
}

/// One row of the table: the `table.json` key, the label in `table.md`, the factor to
/// display it with, and where it comes from in a run's summary.
struct Row {
    key: &'static str,
    label: &'static str,
    scale: f64,
    value: fn(&Summary) -> Option<f64>,
}

/// The metrics of the table, in row order.
const ROWS: [Row; 11] = [
    Row {
        key: "ua_final",
        label: "UA, undetected-set area (%)",
        scale: 100.0,
        value: |s| s.ua_final,
    },
    Row {
        key: "oa_final",
        label: "OA, undetected and occluded (%)",
        scale: 100.0,
        value: |s| s.oa_final,
    },
    Row {
        key: "ua_final_worst",
        label: "UA, worst agent (%)",
        scale: 100.0,
        value: |s| s.ua_final_worst,
    },
    Row {
        key: "oa_final_worst",
        label: "OA, worst agent (%)",
        scale: 100.0,
        value: |s| s.oa_final_worst,
    },
    Row {
        key: "explored_final",
        label: "explored (%)",
        scale: 100.0,
        value: |s| s.explored_final,
    },
    Row {
        key: "target_set_area_mean",
        label: "target-set area, mean (%)",
        scale: 100.0,
        value: |s| s.target_set_area_mean,
    },
    Row {
        key: "loc_error_mean_m",
        label: "localisation error, mean (m)",
        scale: 1.0,
        value: |s| s.loc_error_mean_m,
    },
    Row {
        key: "identified_final",
        label: "identified targets (final)",
        scale: 1.0,
        value: |s| Some(s.identified_final),
    },
    Row {
        key: "violations",
        label: "guarantee violations",
        scale: 1.0,
        value: |s| Some(s.violations as f64),
    },
    Row {
        key: "time_all_identified_s",
        label: "all identified at (s)",
        scale: 1.0,
        value: |s| s.time_all_identified_s,
    },
    Row {
        key: "real_time_factor",
        label: "real-time factor",
        scale: 1.0,
        value: |s| Some(s.real_time_factor),
    },
];

/// `table.json`: per variant, per metric, the statistics over seeds.
#[derive(Clone, Debug, Serialize)]
pub struct Table {
    /// Seeds run per variant.
    pub seeds: Vec<u64>,
    /// Variants in column order.
    pub variants: Vec<Variant>,
    /// `metrics[variant][key]`.
    pub metrics: BTreeMap<&'static str, BTreeMap<&'static str, Cell>>,
    /// Runs that failed or were interrupted, as `variant/seed-n`.
    pub failed_runs: Vec<String>,
}

impl Table {
    /// Builds the table from each variant's runs in seed order, each run as its
    /// [`row_values`] (`None` throughout for a missing run).
    pub fn build(
        seeds: Vec<u64>,
        results: &[(Variant, Vec<Vec<Option<f64>>>)],
        failed: Vec<String>,
    ) -> Table {
        let metrics = results
            .iter()
            .map(|(variant, runs)| {
                let cells = ROWS
                    .iter()
                    .enumerate()
                    .map(|(i, row)| (row.key, Cell::of(runs.iter().map(|r| r[i]).collect())))
                    .collect();
                (variant.name(), cells)
            })
            .collect();
        Table {
            seeds,
            variants: results.iter().map(|(v, _)| *v).collect(),
            metrics,
            failed_runs: failed,
        }
    }

    /// The paper's Table I layout in Markdown: metrics as rows, variants as columns.
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(
            md,
            "Final metrics, mean ± standard deviation over {} seeds ({}); the set metrics \
             are each agent's own, averaged over agents unless marked worst agent.\n",
            self.seeds.len(),
            seed_range(&self.seeds)
        );
        let names: Vec<&str> = self.variants.iter().map(|v| v.name()).collect();
        let _ = writeln!(md, "| metric | {} |", names.join(" | "));
        let _ = writeln!(md, "|---|{}", "---:|".repeat(names.len()));
        for row in &ROWS {
            let cells: Vec<String> = names
                .iter()
                .map(|v| {
                    self.metrics
                        .get(v)
                        .and_then(|m| m.get(row.key))
                        .map_or_else(|| "-".into(), |c| format_cell(c, row.scale))
                })
                .collect();
            let _ = writeln!(md, "| {} | {} |", row.label, cells.join(" | "));
        }
        if !self.failed_runs.is_empty() {
            let _ = writeln!(
                md,
                "\nRuns that did not complete: {}",
                self.failed_runs.join(", ")
            );
        }
        md
    }
}

fn seed_range(seeds: &[u64]) -> String {
    match (seeds.first(), seeds.last()) {
        (Some(a), Some(b)) if a != b => format!("seeds {a}..={b}"),
        (Some(a), _) => format!("seed {a}"),
        _ => "no seed".into(),
    }
}

/// A run's value of every row of the table, in row order.
pub fn row_values(summary: &Summary) -> Vec<Option<f64>> {
    ROWS.iter().map(|row| (row.value)(summary)).collect()
}

/// The same values read from a run's `summary.json` (the rows' keys are its keys).
fn row_values_json(summary: &serde_json::Value) -> Vec<Option<f64>> {
    ROWS.iter()
        .map(|row| summary.get(row.key).and_then(serde_json::Value::as_f64))
        .collect()
}

fn format_cell(cell: &Cell, scale: f64) -> String {
    match (cell.mean, cell.sd) {
        (Some(m), Some(sd)) => {
            let digits = if scale == 100.0 || m.abs() < 10.0 {
                2
            } else {
                1
            };
            format!("{:.digits$} ± {:.digits$}", m * scale, sd * scale)
        }
        _ => "-".into(),
    }
}

/// `fleet sweep`: runs everything, writes the table and the band plot, prints the table.
pub fn run(config: &SweepConfig) -> anyhow::Result<Outcome> {
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("cannot create {}", config.out.display()))?;
    let runtime = runtime()?;
    let mut results: Vec<(Variant, Vec<Vec<Option<f64>>>)> =
        config.variants.iter().map(|&v| (v, Vec::new())).collect();
    let mut series: Vec<(String, Vec<Vec<StepMetrics>>)> = config
        .variants
        .iter()
        .map(|v| (v.name().to_owned(), Vec::new()))
        .collect();
    let mut failed = Vec::new();
    let mut seeds = Vec::new();
    let mut code = Outcome::Success;
    for (i, (variant, seed, run)) in config.runs.iter().enumerate() {
        let label = format!(
            "{}/{} {} seed {seed}",
            i + 1,
            config.runs.len(),
            variant.name()
        );
        let record = runtime.block_on(execute(run, &label))?;
        let summary = write_results(&record)?;
        eprintln!(
            "[{label}] UA {} OA {} violations {} ({:.0} s wall)",
            percent(summary.ua_final),
            percent(summary.oa_final),
            summary.violations,
            summary.wall_s
        );
        if !seeds.contains(seed) {
            seeds.push(*seed);
        }
        let column = config
            .variants
            .iter()
            .position(|v| v == variant)
            .unwrap_or(0);
        if outcome(&record) != Outcome::Success {
            failed.push(format!("{}/seed-{seed}", variant.name()));
            code = Outcome::Failed;
        }
        results[column].1.push(row_values(&summary));
        series[column].1.push(record.series);
        if record.interrupted {
            break;
        }
    }
    let table = Table::build(seeds, &results, failed);
    write_table(&table, &series, &config.out)?;
    Ok(code)
}

/// Writes `table.json`, `table.md` and `metrics.png` into `out` and prints the table.
fn write_table(
    table: &Table,
    series: &[(String, Vec<Vec<StepMetrics>>)],
    out: &Path,
) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(table)? + "\n";
    std::fs::write(out.join("table.json"), json).context("cannot write table.json")?;
    let md = table.to_markdown();
    std::fs::write(out.join("table.md"), &md).context("cannot write table.md")?;
    draw_sweep(series, &out.join("metrics.png"))?;
    println!("{md}\nresults in {}", out.display());
    Ok(())
}

/// One run read back from a sweep directory.
struct FoundRun {
    values: Vec<Option<f64>>,
    series: Vec<StepMetrics>,
    source: PathBuf,
}

/// `fleet sweep --merge`: the table and picture of every run under the sources'
/// `<variant>/seed-<n>/`, variants in the sweep's column order, seeds in order. A run missing
/// for one variant but present for another is listed as missing; the sources' failed runs
/// are carried over.
pub fn merge(config: &MergeConfig) -> anyhow::Result<Outcome> {
    let mut runs: BTreeMap<(Variant, u64), FoundRun> = BTreeMap::new();
    let mut failed = Vec::new();
    for dir in &config.sources {
        anyhow::ensure!(dir.is_dir(), "{} is not a sweep directory", dir.display());
        if let Ok(text) = std::fs::read_to_string(dir.join("table.json")) {
            let table: serde_json::Value = serde_json::from_str(&text)
                .with_context(|| format!("{}: table.json is not JSON", dir.display()))?;
            let listed = table["failed_runs"].as_array().into_iter().flatten();
            failed.extend(listed.filter_map(|f| f.as_str().map(str::to_owned)));
        }
        for variant in Variant::ALL {
            for (seed, run_dir) in seed_dirs(&dir.join(variant.name()))? {
                let run = read_run(&run_dir, variant, seed)?;
                if let Some(other) = runs.insert((variant, seed), run) {
                    anyhow::bail!(
                        "{}/seed-{seed} is in both {} and {}",
                        variant.name(),
                        other.source.display(),
                        dir.display()
                    );
                }
            }
        }
    }
    anyhow::ensure!(
        !runs.is_empty(),
        "no run found under the merged directories (expected <variant>/seed-<n>/summary.json)"
    );
    let seeds: Vec<u64> = runs
        .keys()
        .map(|k| k.1)
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let variants: Vec<Variant> = Variant::ALL
        .into_iter()
        .filter(|v| runs.keys().any(|k| k.0 == *v))
        .collect();
    let mut results = Vec::new();
    let mut series = Vec::new();
    for &variant in &variants {
        let mut values = Vec::new();
        let mut curves = Vec::new();
        for &seed in &seeds {
            match runs.remove(&(variant, seed)) {
                Some(run) => {
                    values.push(run.values);
                    curves.push(run.series);
                }
                None => {
                    failed.push(format!("{}/seed-{seed} (missing)", variant.name()));
                    values.push(vec![None; ROWS.len()]);
                }
            }
        }
        results.push((variant, values));
        series.push((variant.name().to_owned(), curves));
    }
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("cannot create {}", config.out.display()))?;
    let code = if failed.is_empty() {
        Outcome::Success
    } else {
        Outcome::Failed
    };
    write_table(&Table::build(seeds, &results, failed), &series, &config.out)?;
    Ok(code)
}

/// The `seed-<n>` directories under `dir` (none when `dir` does not exist), in seed order.
fn seed_dirs(dir: &Path) -> anyhow::Result<Vec<(u64, PathBuf)>> {
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("cannot read {}", dir.display()))? {
        let path = entry?.path();
        let seed = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix("seed-"))
            .and_then(|n| n.parse().ok());
        if let Some(seed) = seed.filter(|_| path.is_dir()) {
            found.push((seed, path));
        }
    }
    found.sort();
    Ok(found)
}

/// A run's table values and series, checking that its summary is the variant's and seed's.
fn read_run(dir: &Path, variant: Variant, seed: u64) -> anyhow::Result<FoundRun> {
    let read = |name: &str| {
        std::fs::read_to_string(dir.join(name))
            .with_context(|| format!("cannot read {}", dir.join(name).display()))
    };
    let summary: serde_json::Value = serde_json::from_str(&read("summary.json")?)
        .with_context(|| format!("{}: summary.json is not JSON", dir.display()))?;
    anyhow::ensure!(
        summary["variant"] == variant.name() && summary["seed"] == seed,
        "{}: summary.json is of variant {} seed {}, not {} seed {seed}",
        dir.display(),
        summary["variant"],
        summary["seed"],
        variant.name()
    );
    let series = timeseries::from_csv(&read("timeseries.csv")?)
        .with_context(|| format!("{}: timeseries.csv", dir.display()))?;
    Ok(FoundRun {
        values: row_values_json(&summary),
        series,
        source: dir.to_owned(),
    })
}

fn percent(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{:.1} %", v * 100.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    fn summary(ua: f64, oa: Option<f64>) -> Summary {
        Summary {
            ua_final: Some(ua),
            oa_final: oa,
            ..Summary::default()
        }
    }

    #[test]
    fn the_table_has_mean_and_sd_per_variant_and_metric() {
        let results = vec![
            (
                Variant::Nomap,
                vec![
                    row_values(&summary(0.30, Some(0.2))),
                    row_values(&summary(0.20, None)),
                ],
            ),
            (Variant::Paper, vec![row_values(&summary(0.10, Some(0.1)))]),
        ];
        let table = Table::build(vec![1, 2], &results, vec![]);
        let ua = &table.metrics["nomap"]["ua_final"];
        assert!((ua.mean.unwrap() - 0.25).abs() < 1e-12);
        assert!((ua.sd.unwrap() - 0.005_f64.sqrt()).abs() < 1e-12);
        let oa = &table.metrics["nomap"]["oa_final"];
        assert_eq!(oa.values, vec![Some(0.2), None]);
        assert_eq!(oa.sd, Some(0.0));
        let md = table.to_markdown();
        assert!(md.contains("| metric | nomap | paper |"), "{md}");
        assert!(
            md.contains("| UA, undetected-set area (%) | 25.00 ± 7.07 | 10.00 ± 0.00 |"),
            "{md}"
        );
    }

    #[test]
    fn the_rows_read_the_same_values_from_a_summary_and_its_json() {
        let s = Summary {
            ua_final: Some(0.31),
            oa_final_worst: Some(0.2),
            explored_final: Some(0.9),
            loc_error_mean_m: Some(3.5),
            identified_final: 7.5,
            violations: 2,
            time_all_identified_s: None,
            real_time_factor: 4.0,
            ..Summary::default()
        };
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(row_values_json(&json), row_values(&s));
        assert!(row_values(&s).iter().filter(|v| v.is_some()).count() >= 6);
    }

    /// Writes a fake run of `variant` and `seed` under `dir` as a sweep would.
    fn fake_run(dir: &Path, variant: Variant, seed: u64, ua: f64) {
        let run = dir.join(variant.name()).join(format!("seed-{seed}"));
        std::fs::create_dir_all(&run).unwrap();
        let summary = Summary {
            seed,
            variant: variant.name(),
            ua_final: Some(ua),
            ..Summary::default()
        };
        std::fs::write(
            run.join("summary.json"),
            serde_json::to_string(&summary).unwrap(),
        )
        .unwrap();
        let step = StepMetrics {
            step: 1,
            time_s: 0.5,
            mean: Some(crate::observe::metrics::SetMetrics {
                ua,
                ..Default::default()
            }),
            ..StepMetrics::default()
        };
        timeseries::write(&[step], &run.join("timeseries.csv")).unwrap();
    }

    #[test]
    fn merged_sweeps_give_the_table_of_all_their_runs() {
        crate::pictures::register_fonts().unwrap();
        let root = std::env::temp_dir().join(format!("setfleet-merge-{}", std::process::id()));
        let (a, b, out) = (root.join("a"), root.join("b"), root.join("out"));
        fake_run(&a, Variant::Paper, 1, 0.4);
        fake_run(&a, Variant::Paper, 2, 0.6);
        fake_run(&b, Variant::Setfleet, 1, 0.2);
        fake_run(&b, Variant::Setfleet, 2, 0.3);
        fake_run(&b, Variant::Nomap, 2, 0.9);
        let config = MergeConfig {
            sources: vec![a.clone(), b.clone()],
            out: out.clone(),
        };
        // nomap has no seed 1: the table says so and the merge reports a failure.
        assert_eq!(merge(&config).unwrap(), Outcome::Failed);
        let table: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("table.json")).unwrap())
                .unwrap();
        assert_eq!(
            table["variants"],
            serde_json::json!(["nomap", "paper", "setfleet"])
        );
        assert_eq!(table["seeds"], serde_json::json!([1, 2]));
        assert_eq!(table["metrics"]["paper"]["ua_final"]["mean"], 0.5);
        assert_eq!(
            table["metrics"]["nomap"]["ua_final"]["values"],
            serde_json::json!([null, 0.9])
        );
        assert_eq!(
            table["failed_runs"],
            serde_json::json!(["nomap/seed-1 (missing)"])
        );
        assert!(out.join("metrics.png").is_file());
        // A run found twice, or a summary of another run, is an error.
        fake_run(&b, Variant::Paper, 2, 0.6);
        assert!(
            merge(&config)
                .unwrap_err()
                .to_string()
                .contains("paper/seed-2 is in both")
        );
        std::fs::remove_dir_all(b.join("paper")).unwrap();
        std::fs::rename(a.join("paper/seed-2"), a.join("paper/seed-3")).unwrap();
        assert!(
            merge(&config)
                .unwrap_err()
                .to_string()
                .contains("not paper seed 3")
        );
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn variants_are_parsed_and_checked() {
        #[derive(Parser)]
        struct Wrap {
            #[command(flatten)]
            sweep: SweepArgs,
        }
        let w = Wrap::try_parse_from([
            "x",
            "--seeds",
            "2",
            "--variants",
            "paper,nomap",
            "--out",
            "o",
        ])
        .unwrap();
        let c = w.sweep.validate().unwrap();
        assert_eq!(c.runs.len(), 4);
        assert_eq!(c.runs[2].0, Variant::Nomap);
        assert_eq!(c.runs[2].2.scenario.seed, 1);
        assert!(!c.runs[2].2.scenario.guidance.use_map);
        assert_eq!(c.runs[0].2.scenario.guidance.kappa, 1.0);
        assert_eq!(c.runs[3].2.out, PathBuf::from("o/nomap/seed-2"));
        let ids: std::collections::BTreeSet<_> =
            c.runs.iter().map(|r| r.2.run_id.to_string()).collect();
        assert_eq!(ids.len(), 4, "every run has its own id");
        // A merge runs nothing, so it takes no run settings.
        for extra in [
            ["--seeds", "2"],
            ["--variants", "paper"],
            ["--set", "seed=3"],
        ] {
            let args = ["x", "--merge", "a", extra[0], extra[1]];
            assert!(Wrap::try_parse_from(args).is_err(), "{extra:?}");
        }
        let w = Wrap::try_parse_from(["x", "--merge", "a", "b"]).unwrap();
        assert_eq!(w.sweep.merge_config().unwrap().sources.len(), 2);
        let w = Wrap::try_parse_from(["x", "--seeds", "0"]).unwrap();
        assert!(w.sweep.validate().unwrap_err().0.contains("--seeds"));
        assert!(Wrap::try_parse_from(["x", "--seeds", "1", "--variants", "best"]).is_err());
    }
}
