//! Runs read back from sweep directories, and the table and picture made of them.
//!
//! Every table is built from runs as written on disk (`summary.json`, `timeseries.csv`),
//! whether they ran in this process or in another sweep, shard or machine: a sweep, its
//! shards merged, or a sweep with `--jobs` give byte-for-byte the same values, since all of
//! them read the same files the same way.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context as _;

use super::metrics::{METRICS, run_values};
use super::table::Table;
use crate::outcome::Outcome;
use fleet_observe::observe::StepMetrics;
use fleet_observe::results::curves::draw_sweep;
use fleet_observe::results::summary::Summary;
use fleet_observe::results::timeseries;
use protocol::variant::Variant;

/// A validated `fleet sweep --merge`.
#[derive(Debug, Clone)]
pub struct MergeConfig {
    /// The sweep directories read.
    pub sources: Vec<PathBuf>,
    /// The key and values of an axis sweep (`--axis`): each value's runs are read under
    /// `KEY=V/` of every source, and the values compared ([`super::axis`]).
    pub axis: Option<super::Axis>,
    /// Output directory.
    pub out: PathBuf,
}

/// One run read back from a sweep directory.
pub(super) struct FoundRun {
    /// Its value of every metric, in the order of [`METRICS`] ([`run_values`]).
    pub values: Vec<Option<f64>>,
    /// Its metrics per step.
    pub series: Vec<StepMetrics>,
    /// Where it was read.
    pub source: PathBuf,
}

/// Runs by variant and seed.
pub(super) type FoundRuns = BTreeMap<(Variant, u64), FoundRun>;

/// The curves of every run per variant name, for [`draw_sweep`].
type Curves = Vec<(String, Vec<Vec<StepMetrics>>)>;

/// The table and curves of `runs`, columns in the order of `variants`, seeds in order. A
/// (variant, seed) without a run has no values; with `flag_missing` it is listed among the
/// failed runs as missing.
pub(super) fn assemble(
    mut runs: FoundRuns,
    variants: &[Variant],
    mut failed: Vec<String>,
    flag_missing: bool,
) -> (Table, Curves) {
    let seeds: Vec<u64> = runs
        .keys()
        .map(|k| k.1)
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let mut results = Vec::new();
    let mut curves = Vec::new();
    for &variant in variants {
        let mut values = Vec::new();
        let mut series = Vec::new();
        for &seed in &seeds {
            match runs.remove(&(variant, seed)) {
                Some(run) => {
                    values.push(run.values);
                    series.push(run.series);
                }
                None => {
                    if flag_missing {
                        failed.push(format!("{}/seed-{seed} (missing)", variant.name()));
                    }
                    values.push(vec![None; METRICS.len()]);
                }
            }
        }
        results.push((variant, values));
        curves.push((variant.name().to_owned(), series));
    }
    (Table::build(seeds, &results, failed), curves)
}

/// Writes `table.json`, `table.md` and (when there is a run) `metrics.png` into `out` and
/// prints the table.
pub(super) fn write_table(table: &Table, curves: &Curves, out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let json = serde_json::to_string_pretty(table)? + "\n";
    std::fs::write(out.join("table.json"), json).context("cannot write table.json")?;
    let md = table.to_markdown();
    std::fs::write(out.join("table.md"), &md).context("cannot write table.md")?;
    if curves.iter().any(|(_, runs)| !runs.is_empty()) {
        draw_sweep(curves, &out.join("metrics.png"))?;
    }
    println!("{md}\nresults in {}", out.display());
    Ok(())
}

/// `fleet sweep --merge` without an axis: the table and picture of every run under the sources'
/// `<variant>/seed-<n>/`, seeds in order. The columns are the variants that have runs, in
/// the order the sources' `table.json` list them (then in [`Variant::ALL`]'s). A run missing
/// for one variant but present for another is listed as missing; the sources' failed runs
/// are carried over.
pub(super) fn merge(config: &MergeConfig) -> anyhow::Result<Outcome> {
    let table = merge_into(&config.sources, &config.out)?;
    Ok(if table.failed_runs.is_empty() {
        Outcome::Success
    } else {
        Outcome::Failed
    })
}

/// The table of the runs under `sources` (as [`merge`] reads them), written with its picture
/// into `out`.
pub(super) fn merge_into(sources: &[PathBuf], out: &Path) -> anyhow::Result<Table> {
    let (runs, failed, listed) = gather(sources)?;
    anyhow::ensure!(
        !runs.is_empty(),
        "no run found under the merged directories (expected <variant>/seed-<n>/summary.json)"
    );
    let variants = columns(&runs, listed);
    let (table, curves) = assemble(runs, &variants, failed, true);
    write_table(&table, &curves, out)?;
    Ok(table)
}

/// The runs under `<variant>/seed-<n>/` of every directory of `dirs`, the failed runs their
/// `table.json` list, and the variants they list in order.
pub(super) fn gather(dirs: &[PathBuf]) -> anyhow::Result<(FoundRuns, Vec<String>, Vec<Variant>)> {
    let mut runs = FoundRuns::new();
    let mut failed = Vec::new();
    let mut listed = Vec::new();
    for dir in dirs {
        if let Ok(text) = std::fs::read_to_string(dir.join("table.json")) {
            let table: serde_json::Value = serde_json::from_str(&text)
                .with_context(|| format!("{}: table.json is not JSON", dir.display()))?;
            let names = table["failed_runs"].as_array().into_iter().flatten();
            failed.extend(names.filter_map(|f| f.as_str().map(str::to_owned)));
            let variants = table["variants"].as_array().into_iter().flatten();
            listed.extend(variants.filter_map(|v| {
                let name = v.as_str()?;
                Variant::ALL.into_iter().find(|x| x.name() == name)
            }));
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
    Ok((runs, failed, listed))
}

/// The columns of a merged table: the variants that have runs, in the order the sources'
/// tables list them, then in [`Variant::ALL`]'s.
pub(super) fn columns(runs: &FoundRuns, listed: Vec<Variant>) -> Vec<Variant> {
    let mut variants: Vec<Variant> = Vec::new();
    for v in listed.into_iter().chain(Variant::ALL) {
        if !variants.contains(&v) && runs.keys().any(|k| k.0 == v) {
            variants.push(v);
        }
    }
    variants
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
pub(super) fn read_run(dir: &Path, variant: Variant, seed: u64) -> anyhow::Result<FoundRun> {
    let read = |name: &str| {
        std::fs::read_to_string(dir.join(name))
            .with_context(|| format!("cannot read {}", dir.join(name).display()))
    };
    let summary: Summary = serde_json::from_str(&read("summary.json")?)
        .with_context(|| format!("{}: summary.json is not a run's summary", dir.display()))?;
    anyhow::ensure!(
        summary.variant == variant.name() && summary.seed == seed,
        "{}: summary.json is of variant {} seed {}, not {} seed {seed}",
        dir.display(),
        summary.variant,
        summary.seed,
        variant.name()
    );
    let series = timeseries::from_csv(&read("timeseries.csv")?)
        .with_context(|| format!("{}: timeseries.csv", dir.display()))?;
    Ok(FoundRun {
        values: run_values(&summary, &series),
        series,
        source: dir.to_owned(),
    })
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Writes a fake run of `variant` and `seed` under `dir` as a sweep would.
    pub(in crate::sweep) fn fake_run(dir: &Path, variant: Variant, seed: u64, ua: f64) {
        let run = dir.join(variant.name()).join(format!("seed-{seed}"));
        std::fs::create_dir_all(&run).unwrap();
        let summary = Summary {
            seed,
            variant: variant.name().to_owned(),
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
            mean: Some(fleet_observe::observe::metrics::SetMetrics {
                ua,
                ..Default::default()
            }),
            ..StepMetrics::default()
        };
        timeseries::write(&[step], &run.join("timeseries.csv")).unwrap();
    }

    #[test]
    fn merged_sweeps_give_the_table_of_all_their_runs() {
        fleet_observe::pictures::register_fonts().unwrap();
        let root = std::env::temp_dir().join(format!("setfleet-merge-{}", std::process::id()));
        let (a, b, out) = (root.join("a"), root.join("b"), root.join("out"));
        fake_run(&a, Variant::Paper, 1, 0.4);
        fake_run(&a, Variant::Paper, 2, 0.6);
        fake_run(&b, Variant::Setfleet, 1, 0.2);
        fake_run(&b, Variant::Setfleet, 2, 0.3);
        fake_run(&b, Variant::Nomap, 2, 0.9);
        let config = MergeConfig {
            sources: vec![a.clone(), b.clone()],
            axis: None,
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
}
