//! `fleet sweep`: every variant on the same seeds (`--seeds N`: 1..=N; `--seeds A..B`: A to
//! B, both included; [`SeedSet`]), one full run each (as separate processes, like
//! `fleet run`), then the paper's Table I layout: one row per metric, one column per variant,
//! mean ± sample standard deviation over the seeds ([`table`]), and every two variants
//! compared seed by seed ([`paired`]).
//!
//! Writes into `--out`: each run's results under `<variant>/seed-<n>/`, `table.json`,
//! `table.md` and `metrics.png` (UA and OA over time per variant, mean ± 1 sd).
//!
//! **Statistics that can tell.** The table's rows are the final metrics of `summary.json` and
//! four steadier ones, the mean of UA, OA, target-set area and localisation error over
//! simulated time 100 s to 300 s ([`STEADY_WINDOW_S`], from each run's `timeseries.csv`).
//! Since a seed fixes the world, the variants are then compared seed by seed on those four
//! metrics, final and over the window: for each two variants `a` and `b`, the mean of
//! `a − b` over the seeds both ran, its 95 % confidence interval (Student's t), the t
//! statistic, and on how many seeds each was lower (lower is better for all four). A CI that
//! excludes 0 means the difference is measurable on those seeds (`paired` in `table.json`,
//! the second table of `table.md`).
//!
//! A sweep spreads over cores and machines three ways, all giving the same table:
//!
//! - `--jobs N` runs N runs at once ([`jobs`]), each isolated by its own run id;
//! - `--shard K/N` runs only the K-th of N shares of the runs ([`shard`]: run `i` of the
//!   variant-major list goes to shard `i mod N`, K counted from 0), so that a batch system
//!   (a Slurm job array, a Kubernetes indexed Job) runs one shard per task;
//! - `fleet sweep --merge DIR... --out DIR` builds the table and picture from the runs of
//!   several sweeps or shards ([`collect`]), read back from their `summary.json` and
//!   `timeseries.csv`. Every run depends only on its variant and seed, so the merged table
//!   is the one a single sweep of all of them writes. A run found twice is an error.
//!
//! A sweep builds its own table the same way, from its runs' files as written, so its values
//! are those a merge reads.
//!
//! `--axis KEY=V1,V2,...` runs the whole sweep at every value of one scenario key (e.g. the
//! radio's `comms.loss=0,0.1,0.3,0.5`) and compares the values ([`axis`]): each value's runs
//! and table under `KEY=V/`, the comparison in `axis.md`, `axis.json` and `axis.png`.
//!
//! `--scenario DIR` runs the whole sweep on every scenario of a directory (a suite) and
//! compares the variants per scenario ([`suite`]). `--fault F` injects the fault into every
//! run, as `fleet run --fault` does.
//!
//! The variants are those of [`protocol::variant`]: `nomap`, `kappa0`, `paper` (the paper's
//! Table I columns) and `setfleet` (the project's planner).

pub mod axis;
pub mod cache;
pub mod collect;
pub mod jobs;
pub mod metrics;
pub mod paired;
pub mod seeds;
pub mod shard;
pub mod suite;
pub mod table;

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;

use crate::outcome::Outcome;
use crate::run::config::{RunConfig, check_faults, new_run_id};
use crate::run::hosts::HostLayout;
use crate::run::runtime;
pub use axis::Axis;
pub use cache::RunCache;
pub use collect::MergeConfig;
use collect::{FoundRuns, assemble, read_run, write_table};
use fleet_observe::faults::Fault;
use fleet_process::usage::{ScenarioArgs, UsageError};
use jobs::RunEnd;
pub use metrics::STEADY_WINDOW_S;
pub use paired::{Differences, Paired, t_quantile};
pub use protocol::variant::Variant;
pub use seeds::{MAX_SEEDS, SeedSet};
pub use shard::Shard;
pub use suite::Suite;
pub use table::{Cell, Table};

/// `fleet sweep --merge`: the table and picture of the runs under the sources (one table), of
/// each value of `--axis` and the values compared ([`axis::merge`]), or, when every source is
/// a suite's sweep, of each scenario and the suite's comparison ([`suite::merge`]).
pub fn merge(config: &MergeConfig) -> anyhow::Result<Outcome> {
    for dir in &config.sources {
        anyhow::ensure!(dir.is_dir(), "{} is not a sweep directory", dir.display());
    }
    match &config.axis {
        Some(axis) => axis::merge(config, axis),
        None if config.sources.iter().all(|d| suite::is_suite_sweep(d)) => {
            suite::merge(&config.sources, &config.out)
        }
        None => collect::merge(config),
    }
}
use world_server::server::StepMode;

/// Most runs `--jobs` runs at once.
pub const MAX_JOBS: u32 = 256;

/// `fleet sweep`.
#[derive(Debug, Clone, Args)]
pub struct SweepArgs {
    /// The scenario (its seed is replaced by each of --seeds).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// The seeds: a number N (seeds 1..=N) or a range A..B of seeds, both included (also
    /// written A..=B), e.g. 30 or 101..130; at most 1000 seeds.
    #[arg(long, required_unless_present = "merge", value_name = "N|A..B")]
    pub seeds: Option<SeedSet>,
    /// Variants to run, comma-separated, in the table's column order (each is a named set of
    /// scenario settings; `--set` overrides apply after them).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = Variant::ALL.to_vec())]
    pub variants: Vec<Variant>,
    /// Overrides the scenario's `duration_s`, seconds of simulated time.
    #[arg(long)]
    pub duration: Option<f64>,
    /// A fault to inject into every run (repeatable), as `fleet run --fault` takes it:
    /// `kill:UAV@S`, `restart:UAV@S` or `pause:UAV@S+D`, e.g. `kill:2@60`.
    #[arg(long = "fault", value_name = "KIND:UAV@S[+D]")]
    pub faults: Vec<Fault>,
    /// Runs this many runs at once (each with its own processes, run id and shared memory).
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub jobs: u32,
    /// Runs only shard K of N (K counted from 0): run i of the sweep's list (variant-major,
    /// the seeds of --seeds in order) belongs to shard i mod N. Give every shard the same --seeds,
    /// --variants and scenario, then `--merge` their output directories.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<Shard>,
    /// Output directory (default: `runs/sweep-<UTC timestamp>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Runs the sweep at every value of one scenario key, e.g. `comms.loss=0,0.1,0.3,0.5`:
    /// each value's runs and table under `KEY=V/`, and `axis.md`, `axis.json`, `axis.png`
    /// comparing the values (the value wins over a `--set` of the same key).
    #[arg(long, value_name = "KEY=V1,V2,...")]
    pub axis: Option<Axis>,
    /// Runs nothing: builds the table and picture from the runs of these sweep directories.
    /// With `--axis KEY=V1,...`, each value's runs are read under `DIR/KEY=V/`; suite sweeps
    /// (`--scenario DIR`, each with its `suite.json`) merge scenario by scenario.
    #[arg(long, num_args = 1.., value_name = "DIR", conflicts_with_all = ["seeds", "duration", "variants", "scenario", "overrides", "jobs", "shard", "faults", "cache"])]
    pub merge: Vec<PathBuf>,
    /// Keeps every finished run in this directory, by a hash of the binaries, the resolved
    /// scenario, the variant and the faults, and takes a run found there instead of running
    /// it again (lockstep runs are deterministic). Runs with a pause or a restart are never
    /// kept nor taken.
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
}

/// One run of a sweep.
#[derive(Debug, Clone)]
pub struct PlannedRun {
    /// Its variant.
    pub variant: Variant,
    /// Its seed.
    pub seed: u64,
    /// The index of its value of the sweep's `--axis` (0 without one).
    pub level: usize,
    /// Its place in the whole sweep's list (variant-major), from 0: its shard is this
    /// modulo the number of shards.
    pub index: usize,
    /// How it is shown in the progress lines.
    pub label: String,
    /// The run.
    pub config: RunConfig,
}

/// A validated `fleet sweep`: one run configuration per (variant, seed) of its shard.
#[derive(Debug, Clone)]
pub struct SweepConfig {
    /// The shard's runs in order: value-major (with `--axis`), then variant-major.
    pub runs: Vec<PlannedRun>,
    /// The key and values swept (`--axis`).
    pub axis: Option<Axis>,
    /// The scenarios swept (`--scenario DIR`).
    pub suite: Option<Suite>,
    /// Variants in column order.
    pub variants: Vec<Variant>,
    /// Runs at once.
    pub jobs: usize,
    /// The share of the sweep to run (`None`: all of it).
    pub shard: Option<Shard>,
    /// Runs in the whole sweep, every shard's.
    pub total_runs: usize,
    /// Output directory.
    pub out: PathBuf,
    /// Where finished runs are kept and taken from (`--cache`).
    pub cache: Option<PathBuf>,
}

impl SweepArgs {
    /// Checks the counts, the shard and every variant's scenario.
    pub fn validate(&self) -> Result<SweepConfig, UsageError> {
        let seeds = self.seeds.ok_or_else(|| {
            UsageError("--seeds: give the number of seeds N or a range of seeds A..B".into())
        })?;
        if self.jobs == 0 || self.jobs > MAX_JOBS {
            return Err(UsageError(format!(
                "--jobs {}: must be 1 to {MAX_JOBS}",
                self.jobs
            )));
        }
        let mut variants = Vec::new();
        for &v in &self.variants {
            if !variants.contains(&v) {
                variants.push(v);
            }
        }
        if variants.is_empty() {
            return Err(UsageError("--variants: name at least one variant".into()));
        }
        let shard = self.shard.unwrap_or(Shard::WHOLE);
        let out = self
            .out
            .clone()
            .unwrap_or_else(|| crate::run::config::default_out_dir("sweep-"));
        // Bars of several runs at once would overwrite each other: log lines then.
        let progress_bar = self.jobs == 1 && std::io::IsTerminal::is_terminal(&std::io::stderr());
        let suite = match &self.scenario.scenario {
            Some(dir) if dir.is_dir() => Some(Suite::read(dir)?),
            _ => None,
        };
        if suite.is_some() && self.axis.is_some() {
            return Err(UsageError(
                "--axis with a suite (--scenario DIR): sweep the axis on one scenario at a time"
                    .into(),
            ));
        }
        let levels = level_count(suite.as_ref(), self.axis.as_ref());
        let mut all = Vec::new();
        for level in 0..levels {
            for &variant in &variants {
                for seed in seeds.iter() {
                    all.push((level, variant, seed));
                }
            }
        }
        let total_runs = all.len();
        let mine: Vec<(usize, usize, Variant, u64)> = all
            .into_iter()
            .enumerate()
            .filter(|(i, _)| shard.holds(*i))
            .map(|(i, (l, v, s))| (i, l, v, s))
            .collect();
        let mut runs = Vec::with_capacity(mine.len());
        for (n, &(index, level, variant, seed)) in mine.iter().enumerate() {
            let label_of = |at: &str| {
                format!(
                    "{}/{} {at}{} seed {seed}",
                    n + 1,
                    mine.len(),
                    variant.name()
                )
            };
            runs.push(self.planned_run(
                (index, level, variant, seed),
                suite.as_ref(),
                &out,
                progress_bar,
                label_of,
            )?);
        }
        Ok(SweepConfig {
            runs,
            axis: self.axis.clone(),
            suite,
            variants,
            jobs: self.jobs as usize,
            shard: self.shard,
            total_runs,
            out,
            cache: self.cache.clone(),
        })
    }

    /// Run `index` of the whole sweep: `variant` on `seed` at `level` (the axis's value, or
    /// the scenario of `suite`), into its directory under `out`, labelled by `label_of` (given
    /// the level's directory and a space, or nothing).
    fn planned_run(
        &self,
        (index, level, variant, seed): (usize, usize, Variant, u64),
        suite: Option<&Suite>,
        out: &std::path::Path,
        progress_bar: bool,
        label_of: impl Fn(&str) -> String,
    ) -> Result<PlannedRun, UsageError> {
        // What the level changes: the scenario file (a suite's), or one override (an axis's);
        // and the directory of its runs under `out`.
        let (file, setting, dir) = match (suite, &self.axis) {
            (Some(suite), _) => {
                let (name, file) = &suite.scenarios[level];
                (Some(file.clone()), None, Some(name.clone()))
            }
            (None, Some(axis)) => {
                let setting = axis.setting(level);
                (
                    self.scenario.scenario.clone(),
                    Some(setting.clone()),
                    Some(setting),
                )
            }
            (None, None) => (self.scenario.scenario.clone(), None, None),
        };
        let mut overrides = variant.with_user_overrides(&self.scenario.overrides);
        overrides.extend(setting);
        overrides.push(format!("seed={seed}"));
        if let Some(d) = self.duration {
            overrides.push(format!("duration_s={d:?}"));
        }
        let scenario = ScenarioArgs {
            scenario: file,
            overrides,
        }
        .load()?;
        let faults = check_faults(&self.faults, &scenario)?;
        // The run's place in the whole sweep: distinct across shards too.
        let sequence = u32::try_from(index).unwrap_or(u32::MAX);
        let base = dir.as_ref().map_or_else(|| out.to_owned(), |d| out.join(d));
        let at = dir.map(|d| format!("{d} ")).unwrap_or_default();
        Ok(PlannedRun {
            variant,
            seed,
            level,
            index,
            label: label_of(&at),
            config: RunConfig {
                layout: HostLayout::single(scenario.uavs.count),
                scenario,
                mode: StepMode::Lockstep,
                faults,
                out: base.join(variant.name()).join(format!("seed-{seed}")),
                strict: false,
                run_id: new_run_id(sequence),
                progress_bar,
                variant,
                chaos_seed: None,
                listen: None,
                tls: None,
                insecure_links: false,
                view: fleet_observe::viewer::ViewConfig::default(),
            },
        })
    }

    /// The merge this command asks for, `None` when it asks for runs.
    pub fn merge_config(&self) -> Option<MergeConfig> {
        (!self.merge.is_empty()).then(|| MergeConfig {
            sources: self.merge.clone(),
            axis: self.axis.clone(),
            out: self
                .out
                .clone()
                .unwrap_or_else(|| crate::run::config::default_out_dir("sweep-")),
        })
    }
}

/// `fleet sweep`: runs the shard's runs (`--jobs` at once), writes the table of those that
/// ran and the band plot, prints the table. A run that fails is listed in the table's
/// `failed_runs` and does not stop the others; a signal stops the sweep (the runs that
/// completed stay in the table).
pub fn command(config: &SweepConfig) -> anyhow::Result<Outcome> {
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("cannot create {}", config.out.display()))?;
    if let Some(shard) = config.shard {
        eprintln!(
            "fleet: shard {shard}: {} of the sweep's {} runs",
            config.runs.len(),
            config.total_runs
        );
    }
    let cache = config.cache.as_deref().map(RunCache::open).transpose()?;
    let levels = level_count(config.suite.as_ref(), config.axis.as_ref());
    let mut found: Vec<FoundRuns> = (0..levels).map(|_| FoundRuns::new()).collect();
    let mut failed: Vec<(usize, String)> = Vec::new();
    let mut taken = 0;
    let all = jobs::run_all(&config.runs, config.jobs, cache.as_ref(), |i, end| {
        let run = &config.runs[i];
        let name = format!("{}/seed-{}", run.variant.name(), run.seed);
        let ok = match end {
            RunEnd::Done {
                summary,
                interrupted,
                failed,
                cached,
            } => {
                taken += usize::from(cached);
                eprintln!(
                    "[{}] UA {} OA {} violations {} ({}){}",
                    run.label,
                    percent(summary.ua_final),
                    percent(summary.oa_final),
                    summary.violations,
                    if cached {
                        "from the cache".to_owned()
                    } else {
                        format!("{:.0} s wall", summary.wall_s)
                    },
                    if interrupted { ", interrupted" } else { "" }
                );
                match read_run(&run.config.out, run.variant, run.seed) {
                    Ok(r) => {
                        found[run.level].insert((run.variant, run.seed), r);
                        !failed
                    }
                    Err(e) => {
                        eprintln!("fleet: [{}] {e:#}", run.label);
                        false
                    }
                }
            }
            RunEnd::Error(e) => {
                eprintln!("fleet: [{}] the run failed: {e:#}", run.label);
                false
            }
        };
        if !ok {
            failed.push((i, name));
        }
    });
    let interrupted = runtime()?.block_on(all)?;
    if cache.is_some() {
        eprintln!(
            "fleet: {taken} of {} run(s) taken from the cache",
            config.runs.len()
        );
    }
    failed.sort();
    let code = if failed.is_empty() && !interrupted {
        Outcome::Success
    } else {
        Outcome::Failed
    };
    let failed_at: Vec<Vec<String>> = (0..levels)
        .map(|level| {
            failed
                .iter()
                .filter(|(i, _)| config.runs[*i].level == level)
                .map(|(_, name)| name.clone())
                .collect()
        })
        .collect();
    if let Some(suite) = &config.suite {
        let mut tables = Vec::with_capacity(levels);
        for ((found, failed), (name, _)) in found.into_iter().zip(failed_at).zip(&suite.scenarios) {
            let (mut table, curves) = assemble(found, &config.variants, failed, false);
            table.shard = config.shard.map(|s| s.to_string());
            write_table(&table, &curves, &config.out.join(name))?;
            tables.push(table);
        }
        suite::write(suite, &tables, &config.out)?;
        return Ok(code);
    }
    let Some(axis) = &config.axis else {
        let failed = failed_at.into_iter().next().unwrap_or_default();
        let found = found.pop().unwrap_or_default();
        let (mut table, curves) = assemble(found, &config.variants, failed, false);
        table.shard = config.shard.map(|s| s.to_string());
        write_table(&table, &curves, &config.out)?;
        return Ok(code);
    };
    let levels = axis::Levels {
        axis,
        variants: &config.variants,
        shard: config.shard,
        flag_missing: false,
    };
    levels.write(found, failed_at, &config.out)?;
    Ok(code)
}

/// How many sets of runs a sweep has: one per scenario of a suite, or per value of an axis,
/// else one.
fn level_count(suite: Option<&Suite>, axis: Option<&Axis>) -> usize {
    match (suite, axis) {
        (Some(suite), _) => suite.scenarios.len(),
        (None, Some(axis)) => axis.values.len(),
        (None, None) => 1,
    }
}

fn percent(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{:.1} %", v * 100.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

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
        assert_eq!(c.runs[2].variant, Variant::Nomap);
        assert_eq!(c.runs[2].config.scenario.seed, 1);
        assert!(!c.runs[2].config.scenario.guidance.use_map);
        assert_eq!(c.runs[0].config.scenario.guidance.kappa, 1.0);
        assert_eq!(c.runs[3].config.out, PathBuf::from("o/nomap/seed-2"));
        assert_eq!((c.jobs, c.shard, c.total_runs), (1, None, 4));
        let ids: std::collections::BTreeSet<_> =
            c.runs.iter().map(|r| r.config.run_id.to_string()).collect();
        assert_eq!(ids.len(), 4, "every run has its own id");
        // A merge runs nothing, so it takes no run settings.
        for extra in [
            ["--seeds", "2"],
            ["--variants", "paper"],
            ["--set", "seed=3"],
            ["--jobs", "2"],
            ["--shard", "0/2"],
            ["--fault", "kill:1@5"],
        ] {
            let args = ["x", "--merge", "a", extra[0], extra[1]];
            assert!(Wrap::try_parse_from(args).is_err(), "{extra:?}");
        }
        let w = Wrap::try_parse_from(["x", "--merge", "a", "b"]).unwrap();
        assert_eq!(w.sweep.merge_config().unwrap().sources.len(), 2);
        // Every run gets the faults, checked against its scenario.
        let with_fault = |fault: &str| {
            let args = ["x", "--seeds", "2", "--variants", "paper", "--fault", fault];
            Wrap::try_parse_from(args).unwrap().sweep.validate()
        };
        let c = with_fault("kill:2@60").unwrap();
        assert!(c.runs.iter().all(|r| r.config.faults.len() == 1));
        assert_eq!(c.runs[1].config.faults[0].to_string(), "kill:2@60");
        assert!(
            with_fault("kill:9@60").is_err(),
            "no UAV 9 in the default fleet"
        );
        for bad in ["0", "5..2", "a..b", "1001"] {
            let e = Wrap::try_parse_from(["x", "--seeds", bad]).err().unwrap();
            assert!(e.to_string().contains("--seeds"), "{bad}: {e}");
        }
        assert!(Wrap::try_parse_from(["x", "--seeds", "1", "--variants", "best"]).is_err());
    }

    #[derive(Parser)]
    struct Wrap {
        #[command(flatten)]
        sweep: SweepArgs,
    }

    /// The validated `fleet sweep ARGS`.
    pub(in crate::sweep) fn parse(args: &[&str]) -> SweepConfig {
        let w = Wrap::try_parse_from(["x"].iter().chain(args)).unwrap();
        w.sweep.validate().unwrap()
    }

    /// The (variant, seed, index) of every run of `fleet sweep ARGS`.
    fn planned(args: &[&str]) -> Vec<(Variant, u64, usize)> {
        parse(args)
            .runs
            .iter()
            .map(|r| (r.variant, r.seed, r.index))
            .collect()
    }

    #[test]
    fn shards_split_the_variant_major_list_round_robin() {
        let base = ["--seeds", "3", "--variants", "setfleet,nomap", "--out", "o"];
        let whole = planned(&base);
        assert_eq!(whole.len(), 6);
        assert_eq!(whole[3], (Variant::Nomap, 1, 3));
        let mut union = Vec::new();
        for k in 0..4 {
            let shard = format!("{k}/4");
            let mine = planned(&[&base[..], &["--shard", &shard]].concat());
            assert!(mine.iter().all(|r| r.2 % 4 == k), "{shard}: {mine:?}");
            union.extend(mine);
        }
        union.sort_by_key(|r| r.2);
        assert_eq!(union, whole, "the shards hold every run once");
        // Shard 1 of 4: runs 1 and 5, setfleet seed 2 and nomap seed 3.
        let one = planned(&[&base[..], &["--shard", "1/4"]].concat());
        assert_eq!(one, vec![(Variant::Setfleet, 2, 1), (Variant::Nomap, 3, 5)]);
        // More shards than runs: the last ones are empty, which is fine.
        assert!(planned(&[&base[..], &["--shard", "9/10"]].concat()).is_empty());
        // A run's id is distinct across shards and its label counts within the shard.
        let w = Wrap::try_parse_from(["x", "--seeds", "3", "--shard", "1/5"]).unwrap();
        let c = w.sweep.validate().unwrap();
        assert_eq!(c.total_runs, 12);
        assert_eq!(c.runs.len(), 3);
        assert!(c.runs[2].config.run_id.as_str().ends_with("-11"));
        assert!(c.runs[1].label.starts_with("2/3 "), "{}", c.runs[1].label);
    }

    #[test]
    fn a_range_of_seeds_runs_those_seeds_and_shards_them_alike() {
        let whole = planned(&["--seeds", "101..103", "--variants", "paper,nomap"]);
        let seeds: Vec<u64> = whole.iter().map(|r| r.1).collect();
        assert_eq!(seeds, [101, 102, 103, 101, 102, 103]);
        assert_eq!(
            whole,
            planned(&["--seeds", "101..=103", "--variants", "paper,nomap"])
        );
        assert_eq!(whole[3], (Variant::Nomap, 101, 3));
        let one = planned(&[
            "--seeds",
            "101..103",
            "--variants",
            "paper,nomap",
            "--shard",
            "1/4",
        ]);
        assert_eq!(
            one,
            vec![(Variant::Paper, 102, 1), (Variant::Nomap, 103, 5)]
        );
        let w = Wrap::try_parse_from(["x", "--seeds", "7..8", "--out", "o"]).unwrap();
        let c = w.sweep.validate().unwrap();
        assert_eq!(c.runs[1].config.scenario.seed, 8);
        assert_eq!(c.runs[1].config.out, PathBuf::from("o/nomap/seed-8"));
        assert!(
            c.runs[1].label.ends_with("nomap seed 8"),
            "{}",
            c.runs[1].label
        );
    }

    #[test]
    fn an_axis_runs_the_sweep_at_every_value_of_its_key() {
        let w = Wrap::try_parse_from([
            "x",
            "--seeds",
            "2",
            "--variants",
            "paper",
            "--axis",
            "comms.loss=0,0.5",
            "--set",
            "comms.loss=0.9",
            "--out",
            "o",
        ])
        .unwrap();
        let c = w.sweep.validate().unwrap();
        assert_eq!(c.runs.len(), 4);
        let r = &c.runs[3];
        assert_eq!((r.level, r.seed, r.index), (1, 2, 3));
        assert_eq!(
            r.config.scenario.comms.loss, 0.5,
            "the axis wins over --set"
        );
        assert_eq!(c.runs[0].config.scenario.comms.loss, 0.0);
        assert_eq!(r.config.out, PathBuf::from("o/comms.loss=0.5/paper/seed-2"));
        assert!(
            r.label.contains("comms.loss=0.5 paper seed 2"),
            "{}",
            r.label
        );
        assert_eq!(c.axis.as_ref().map(|a| a.values.len()), Some(2));
        // A value out of the key's range, or a key the scenario does not have, runs nothing.
        for (axis, says) in [
            ("comms.loss=0,2", "comms.loss"),
            ("comms.lost=0,1", "unknown key `comms.lost`"),
        ] {
            let w = Wrap::try_parse_from(["x", "--seeds", "1", "--axis", axis]).unwrap();
            let e = w.sweep.validate().unwrap_err().0;
            assert!(e.contains(says), "{axis}: {e}");
        }
        assert!(Wrap::try_parse_from(["x", "--seeds", "1", "--axis", "comms.loss"]).is_err());
        let w = Wrap::try_parse_from(["x", "--merge", "a", "--axis", "comms.loss=0,1"]).unwrap();
        let merge = w.sweep.merge_config().unwrap();
        assert_eq!(
            merge.axis.map(|a| a.values),
            Some(vec!["0".into(), "1".into()])
        );
    }

    #[test]
    fn jobs_and_shards_are_checked() {
        let parse = |extra: &[&str]| {
            Wrap::try_parse_from([&["x", "--seeds", "2"][..], extra].concat())
                .map_err(|e| e.to_string())
                .and_then(|w| w.sweep.validate().map_err(|e| e.0))
        };
        assert_eq!(parse(&["--jobs", "3"]).unwrap().jobs, 3);
        assert!(
            parse(&["--jobs", "0"])
                .unwrap_err()
                .contains("--jobs 0: must be 1")
        );
        assert!(parse(&["--jobs", "100000"]).is_err());
        assert!(parse(&["--jobs", "-1"]).is_err());
        for (shard, says) in [
            ("4/4", "shard 4 does not exist"),
            ("1/0", "must be at least 1"),
            ("1-4", "expected K/N"),
            ("one/4", "expected K/N"),
        ] {
            let err = parse(&["--shard", shard]).unwrap_err();
            assert!(
                err.contains("--shard") && err.contains(says),
                "{shard}: {err}"
            );
        }
        let c = parse(&["--shard", "3/4", "--jobs", "2"]).unwrap();
        assert_eq!(c.shard, Shard::new(3, 4));
        assert_eq!(c.runs.len(), 2);
    }
}
