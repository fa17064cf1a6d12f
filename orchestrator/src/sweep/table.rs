//! The sweep's table: the paper's Table I layout, one row per metric, one column per
//! variant, mean ± sample standard deviation over the seeds (`table.json`, `table.md`), then
//! every two variants compared seed by seed ([`super::paired`]).
//!
//! Most rows are values of each run's `summary.json`, read into [`SummaryValues`]: UA, OA and
//! explored ground at the last step, the target-set area and localisation error averaged over
//! the run, and so on. Four rows are steadier: the mean of UA, OA, target-set area and
//! localisation error over the steps of [`STEADY_WINDOW_S`] (simulated time 100 s to 300 s,
//! both included), read from the run's `timeseries.csv` (each step's mean over agents). They
//! leave out the first 100 s, in which every variant starts from the same unknown region, and
//! do not hang on the last step alone. A run shorter than 100 s has no value in them; a run
//! that ends inside the window is averaged over the steps of the window it has.
//!
//! `table.json` holds, per variant and row key, the mean, the standard deviation and the
//! value of every seed ([`Cell`]), the window (`steady_window_s`) and the comparisons
//! (`paired`, [`Paired`]); `table.md` the same as two Markdown tables.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use super::paired::{self, Paired};
use fleet_observe::observe::StepMetrics;
use fleet_observe::observe::metrics::SetMetrics;
use fleet_observe::results::curves::mean_sd;
use protocol::variant::Variant;

/// The steady window of the `*_window` rows and of the paired comparisons: the steps whose
/// simulated time `t` (seconds) has `100 <= t <= 300`.
pub const STEADY_WINDOW_S: (f64, f64) = (100.0, 300.0);

/// How far a step's time may stray from a bound of [`STEADY_WINDOW_S`] and count as on it
/// (step times are multiples of the step period, which a float may miss by an ulp).
const WINDOW_SLACK_S: f64 = 1e-9;

/// The steady window as the tables write it: `100-300 s`.
pub fn window_text() -> String {
    format!("{}-{} s", STEADY_WINDOW_S.0, STEADY_WINDOW_S.1)
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
    /// The statistics of the values of each seed (`None` where a run has none).
    pub(super) fn of(values: Vec<Option<f64>>) -> Cell {
        let present: Vec<f64> = values.iter().flatten().copied().collect();
        let stats = mean_sd(&present);
        Cell {
            mean: stats.map(|s| s.0),
            sd: stats.map(|s| s.1),
            values,
        }
    }
}

/// What the table reads of a run's `summary.json`: the values of its rows, under the same
/// keys. A key that is absent or `null` is no value.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
pub struct SummaryValues {
    /// UA at the last step, mean over agents.
    pub ua_final: Option<f64>,
    /// OA at the last step, mean over agents.
    pub oa_final: Option<f64>,
    /// UA of the worst agent at the last step.
    pub ua_final_worst: Option<f64>,
    /// OA of the worst agent at the last step.
    pub oa_final_worst: Option<f64>,
    /// Explored ground at the last step.
    pub explored_final: Option<f64>,
    /// Target-set area, mean over the run.
    pub target_set_area_mean: Option<f64>,
    /// Localisation error, mean over the run, metres.
    pub loc_error_mean_m: Option<f64>,
    /// Targets identified at the last step.
    pub identified_final: Option<f64>,
    /// Guarantee violations.
    pub violations: Option<f64>,
    /// When every target was identified, seconds.
    pub time_all_identified_s: Option<f64>,
    /// Simulated over wall time.
    pub real_time_factor: Option<f64>,
}

/// Where a row's value of a run comes from.
pub(super) enum Source {
    /// A value of the run's `summary.json`.
    Summary(fn(&SummaryValues) -> Option<f64>),
    /// The mean of a per-step value (of the step's mean over agents) over the steps of
    /// [`STEADY_WINDOW_S`] that have it; `unit` goes in the label.
    Window {
        step: fn(&SetMetrics) -> Option<f64>,
        unit: &'static str,
    },
}

/// One row of the table: the `table.json` key, the label in `table.md`, the factor to
/// display it with, and where a run's value comes from.
pub(super) struct Row {
    pub(super) key: &'static str,
    label: &'static str,
    pub(super) scale: f64,
    source: Source,
}

impl Row {
    /// The row's label in `table.md`; a window row's names the window.
    pub(super) fn label(&self) -> Cow<'static, str> {
        match self.source {
            Source::Summary(_) => Cow::Borrowed(self.label),
            Source::Window { unit, .. } => Cow::Owned(format!(
                "{}, mean over {} ({unit})",
                self.label,
                window_text()
            )),
        }
    }
}

/// How many rows the table has.
pub(super) const ROW_COUNT: usize = ROWS.len();

/// The metrics of the table, in row order.
pub(super) const ROWS: [Row; 15] = [
    Row {
        key: "ua_final",
        label: "UA, undetected-set area (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.ua_final),
    },
    Row {
        key: "oa_final",
        label: "OA, undetected and occluded (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.oa_final),
    },
    Row {
        key: "ua_final_worst",
        label: "UA, worst agent (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.ua_final_worst),
    },
    Row {
        key: "oa_final_worst",
        label: "OA, worst agent (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.oa_final_worst),
    },
    Row {
        key: "explored_final",
        label: "explored (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.explored_final),
    },
    Row {
        key: "target_set_area_mean",
        label: "target-set area, mean (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.target_set_area_mean),
    },
    Row {
        key: "loc_error_mean_m",
        label: "localisation error, mean (m)",
        scale: 1.0,
        source: Source::Summary(|s| s.loc_error_mean_m),
    },
    Row {
        key: "ua_window",
        label: "UA",
        scale: 100.0,
        source: Source::Window {
            step: |m| Some(m.ua),
            unit: "%",
        },
    },
    Row {
        key: "oa_window",
        label: "OA",
        scale: 100.0,
        source: Source::Window {
            step: |m| Some(m.oa),
            unit: "%",
        },
    },
    Row {
        key: "target_set_area_window",
        label: "target-set area",
        scale: 100.0,
        source: Source::Window {
            step: |m| m.target_set_area,
            unit: "%",
        },
    },
    Row {
        key: "loc_error_m_window",
        label: "localisation error",
        scale: 1.0,
        source: Source::Window {
            step: |m| m.loc_error_m,
            unit: "m",
        },
    },
    Row {
        key: "identified_final",
        label: "identified targets (final)",
        scale: 1.0,
        source: Source::Summary(|s| s.identified_final),
    },
    Row {
        key: "violations",
        label: "guarantee violations",
        scale: 1.0,
        source: Source::Summary(|s| s.violations),
    },
    Row {
        key: "time_all_identified_s",
        label: "all identified at (s)",
        scale: 1.0,
        source: Source::Summary(|s| s.time_all_identified_s),
    },
    Row {
        key: "real_time_factor",
        label: "real-time factor",
        scale: 1.0,
        source: Source::Summary(|s| s.real_time_factor),
    },
];

/// A metric every two variants are compared on seed by seed ([`super::paired`]); lower is
/// better for each.
pub(super) struct Compared {
    /// Its name in `paired` of `table.json`.
    pub(super) metric: &'static str,
    /// Its name in `table.md`'s comparison, with the unit of a difference.
    pub(super) label: &'static str,
    /// The keys of its two rows: the value of `summary.json`, the mean over the window.
    pub(super) rows: [&'static str; 2],
}

impl Compared {
    /// The factor its differences are displayed with: its rows' (100 for fractions, so
    /// percentage points).
    pub(super) fn scale(&self) -> f64 {
        ROWS.iter()
            .find(|r| r.key == self.rows[0])
            .map_or(1.0, |r| r.scale)
    }
}

/// The metrics compared, in the order of `paired`.
pub(super) const COMPARED: [Compared; 4] = [
    Compared {
        metric: "ua",
        label: "UA (pp)",
        rows: ["ua_final", "ua_window"],
    },
    Compared {
        metric: "oa",
        label: "OA (pp)",
        rows: ["oa_final", "oa_window"],
    },
    Compared {
        metric: "target_set_area",
        label: "target-set area (pp)",
        rows: ["target_set_area_mean", "target_set_area_window"],
    },
    Compared {
        metric: "loc_error_m",
        label: "localisation error (m)",
        rows: ["loc_error_mean_m", "loc_error_m_window"],
    },
];

/// `table.json`: per variant, per metric, the statistics over seeds, and every two variants
/// compared seed by seed.
#[derive(Clone, Debug, Serialize)]
pub struct Table {
    /// Seeds of the runs, in order (every variant's runs are of these seeds).
    pub seeds: Vec<u64>,
    /// Variants in column order.
    pub variants: Vec<Variant>,
    /// `metrics[variant][key]`.
    pub metrics: BTreeMap<&'static str, BTreeMap<&'static str, Cell>>,
    /// The window of the `*_window` rows, `[from, to]` seconds of simulated time, both
    /// included ([`STEADY_WINDOW_S`]).
    pub steady_window_s: [f64; 2],
    /// Every two variants (in column order) compared seed by seed on UA, OA, target-set area
    /// and localisation error, each by its final value and by its window mean.
    pub paired: Vec<Paired>,
    /// Runs that failed or were interrupted, as `variant/seed-n`.
    pub failed_runs: Vec<String>,
    /// The share of the sweep these runs are (`K/N` of `--shard`), absent for a whole sweep
    /// or a merge.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<String>,
}

impl Table {
    /// Builds the table from each variant's runs in seed order, each run as its values of the
    /// rows in row order (`None` throughout for a missing run).
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
                    .map(|(i, row)| {
                        let values = runs.iter().map(|r| r.get(i).copied().flatten());
                        (row.key, Cell::of(values.collect()))
                    })
                    .collect();
                (variant.name(), cells)
            })
            .collect();
        Table {
            seeds,
            variants: results.iter().map(|(v, _)| *v).collect(),
            metrics,
            steady_window_s: [STEADY_WINDOW_S.0, STEADY_WINDOW_S.1],
            paired: paired::compare(results),
            failed_runs: failed,
            shard: None,
        }
    }

    /// The paper's Table I layout in Markdown: metrics as rows, variants as columns; then
    /// the paired comparisons.
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(
            md,
            "Final metrics, and four means over {} of simulated time, mean ± standard \
             deviation over {} seeds ({}); the set metrics are each agent's own, averaged over \
             agents unless marked worst agent.\n",
            window_text(),
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
            let _ = writeln!(md, "| {} | {} |", row.label(), cells.join(" | "));
        }
        paired::to_markdown(&self.paired, &mut md);
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

/// The seeds as runs of consecutive ones: "seeds 1..=5", "seeds 1..=10, 21..=30",
/// "seeds 2, 4", "seed 3" or "no seed"; past five runs, the first and last seed and
/// "with gaps".
pub(super) fn seed_range(seeds: &[u64]) -> String {
    let mut runs: Vec<(u64, u64)> = Vec::new();
    for &seed in seeds {
        match runs.last_mut() {
            Some((_, last)) if last.checked_add(1) == Some(seed) => *last = seed,
            _ => runs.push((seed, seed)),
        }
    }
    let text = |&(a, b): &(u64, u64)| {
        if a == b {
            a.to_string()
        } else {
            format!("{a}..={b}")
        }
    };
    match (runs.as_slice(), seeds) {
        ([], _) => "no seed".into(),
        (_, [one]) => format!("seed {one}"),
        (runs, _) if runs.len() > 5 => format!(
            "seeds {}..={} with gaps",
            seeds.first().copied().unwrap_or_default(),
            seeds.last().copied().unwrap_or_default()
        ),
        (runs, _) => {
            let parts: Vec<String> = runs.iter().map(text).collect();
            format!("seeds {}", parts.join(", "))
        }
    }
}

/// A run's value of every row of the table, in row order: from its summary's values and its
/// series of metrics per step (its `timeseries.csv`).
pub(super) fn run_values(summary: &SummaryValues, series: &[StepMetrics]) -> Vec<Option<f64>> {
    ROWS.iter()
        .map(|row| match row.source {
            Source::Summary(value) => value(summary),
            Source::Window { step, .. } => window_mean(series, step),
        })
        .collect()
}

/// The mean of `value` of each step's mean over agents, over the steps of [`STEADY_WINDOW_S`]
/// that have one; `None` when none has.
fn window_mean(series: &[StepMetrics], value: fn(&SetMetrics) -> Option<f64>) -> Option<f64> {
    let (from, to) = STEADY_WINDOW_S;
    let values: Vec<f64> = series
        .iter()
        .filter(|m| m.time_s >= from - WINDOW_SLACK_S && m.time_s <= to + WINDOW_SLACK_S)
        .filter_map(|m| m.mean.as_ref().and_then(value))
        .collect();
    (!values.is_empty()).then(|| values.iter().sum::<f64>() / values.len() as f64)
}

/// The digits a value of a row of factor `scale` is shown with: 2 for percentages and small
/// values, 1 for the others.
pub(super) fn digits(value: f64, scale: f64) -> usize {
    if scale == 100.0 || value.abs() < 10.0 {
        2
    } else {
        1
    }
}

/// "mean ± sd" of a cell, times `scale`, or "-".
pub(super) fn format_cell(cell: &Cell, scale: f64) -> String {
    match (cell.mean, cell.sd) {
        (Some(m), Some(sd)) => {
            let digits = digits(m, scale);
            format!("{:.digits$} ± {:.digits$}", m * scale, sd * scale)
        }
        _ => "-".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fleet_observe::results::summary::Summary;

    /// The row values of a run with these final UA and OA and no time series.
    fn values(ua: f64, oa: Option<f64>) -> Vec<Option<f64>> {
        let summary = SummaryValues {
            ua_final: Some(ua),
            oa_final: oa,
            ..SummaryValues::default()
        };
        run_values(&summary, &[])
    }

    fn row(key: &str) -> usize {
        ROWS.iter().position(|r| r.key == key).unwrap()
    }

    #[test]
    fn the_table_has_mean_and_sd_per_variant_and_metric() {
        let results = vec![
            (
                Variant::Nomap,
                vec![values(0.30, Some(0.2)), values(0.20, None)],
            ),
            (Variant::Paper, vec![values(0.10, Some(0.1))]),
        ];
        let table = Table::build(vec![1, 2], &results, vec![]);
        let ua = &table.metrics["nomap"]["ua_final"];
        assert!((ua.mean.unwrap() - 0.25).abs() < 1e-12);
        assert!((ua.sd.unwrap() - 0.005_f64.sqrt()).abs() < 1e-12);
        let oa = &table.metrics["nomap"]["oa_final"];
        assert_eq!(oa.values, vec![Some(0.2), None]);
        assert_eq!(oa.sd, Some(0.0));
        assert_eq!(table.metrics["paper"]["ua_window"].mean, None);
        let md = table.to_markdown();
        assert!(md.contains("| metric | nomap | paper |"), "{md}");
        assert!(
            md.contains("| UA, undetected-set area (%) | 25.00 ± 7.07 | 10.00 ± 0.00 |"),
            "{md}"
        );
        assert!(
            md.contains("| UA, mean over 100-300 s (%) | - | - |"),
            "{md}"
        );
        assert!(
            md.contains("| localisation error, mean over 100-300 s (m) | - | - |"),
            "{md}"
        );
    }

    #[test]
    fn the_rows_read_the_summary_by_its_own_keys() {
        let s = Summary {
            ua_final: Some(0.31),
            oa_final: Some(0.25),
            ua_final_worst: Some(0.4),
            oa_final_worst: Some(0.2),
            explored_final: Some(0.9),
            target_set_area_mean: Some(0.01),
            loc_error_mean_m: Some(3.5),
            identified_final: 7.5,
            violations: 2,
            time_all_identified_s: Some(42.0),
            real_time_factor: 4.0,
            ..Summary::default()
        };
        let json = serde_json::to_value(&s).unwrap();
        let read = SummaryValues::deserialize(&json).unwrap();
        let values = run_values(&read, &[]);
        // Every row from the summary reads the value its key names, and every such key has one.
        for (i, row) in ROWS.iter().enumerate() {
            if matches!(row.source, Source::Summary(_)) {
                assert_eq!(values[i], json[row.key].as_f64(), "{}", row.key);
                assert!(values[i].is_some(), "{}", row.key);
            } else {
                assert_eq!(values[i], None, "{}: no series, no window mean", row.key);
            }
        }
        // A summary without a key, or with null, has no value there.
        let sparse = serde_json::json!({"ua_final": null, "violations": 0, "other": "x"});
        let read = SummaryValues::deserialize(&sparse).unwrap();
        assert_eq!((read.ua_final, read.violations), (None, Some(0.0)));
    }

    /// A step at `time_s` whose mean over agents has these UA and localisation error.
    fn step(time_s: f64, ua: f64, error: Option<f64>) -> StepMetrics {
        StepMetrics {
            time_s,
            mean: Some(SetMetrics {
                ua,
                loc_error_m: error,
                ..SetMetrics::default()
            }),
            ..StepMetrics::default()
        }
    }

    #[test]
    fn the_window_rows_average_the_steps_from_100_to_300_s() {
        assert_eq!(STEADY_WINDOW_S, (100.0, 300.0));
        assert_eq!(window_text(), "100-300 s");
        let series = [
            step(99.5, 0.9, Some(50.0)),
            step(100.0, 0.4, None),
            step(200.0, 0.2, Some(4.0)),
            // A step time a float's rounding put just past the bound is still on it.
            step(300.000_000_000_000_06, 0.3, Some(2.0)),
            step(300.5, 0.9, Some(50.0)),
            StepMetrics {
                time_s: 250.0,
                ..StepMetrics::default()
            },
        ];
        let values = run_values(&SummaryValues::default(), &series);
        assert!((values[row("ua_window")].unwrap() - 0.3).abs() < 1e-12);
        assert_eq!(values[row("loc_error_m_window")], Some(3.0));
        assert_eq!(values[row("target_set_area_window")], None);
        // A run shorter than 100 s has no window mean.
        let short = [step(50.0, 0.5, Some(1.0)), step(99.0, 0.5, Some(1.0))];
        let values = run_values(&SummaryValues::default(), &short);
        assert_eq!(values[row("ua_window")], None);
        // Every compared metric has both its rows.
        for c in &COMPARED {
            for key in c.rows {
                assert!(ROWS.iter().any(|r| r.key == key), "{key}");
            }
        }
    }

    #[test]
    fn the_table_compares_every_two_variants_seed_by_seed() {
        // UA of three variants on seeds 1..=4; setfleet has no seed 4.
        let run = |ua: f64, window: Option<f64>| {
            let mut v = values(ua, None);
            v[row("ua_window")] = window;
            v
        };
        let results = vec![
            (
                Variant::Paper,
                vec![
                    run(0.50, Some(0.6)),
                    run(0.40, Some(0.5)),
                    run(0.45, Some(0.4)),
                    run(0.30, None),
                ],
            ),
            (
                Variant::Setfleet,
                vec![
                    run(0.30, Some(0.3)),
                    run(0.30, Some(0.4)),
                    run(0.45, Some(0.4)),
                    vec![None; ROW_COUNT],
                ],
            ),
            (Variant::Nomap, vec![run(0.5, None); 4]),
        ];
        let table = Table::build(vec![1, 2, 3, 4], &results, vec![]);
        // Three pairs, four metrics, two windows each, in column order.
        assert_eq!(table.paired.len(), 3 * 4 * 2);
        let first = &table.paired[0];
        assert_eq!(
            (
                first.a,
                first.b,
                first.compared.metric,
                first.compared.window
            ),
            (
                Variant::Paper,
                Variant::Setfleet,
                "ua",
                paired::Window::Final
            )
        );
        // d = 0.2, 0.1, 0 on seeds 1 to 3: mean 0.1, sd 0.1.
        let d = &first.compared.differences;
        assert_eq!((d.n, d.a_better, d.b_better, d.ties), (3, 0, 2, 1));
        assert!((d.mean.unwrap() - 0.1).abs() < 1e-12);
        assert!((d.sd.unwrap() - 0.1).abs() < 1e-12);
        let steady = &table.paired[1];
        assert_eq!(steady.compared.window, paired::Window::Steady);
        assert_eq!(steady.compared.differences.n, 3);
        let last = table.paired.last().unwrap();
        assert_eq!(
            (last.a, last.b, last.compared.metric),
            (Variant::Setfleet, Variant::Nomap, "loc_error_m")
        );
        assert_eq!(last.compared.differences.n, 0);
        let json = serde_json::to_value(&table).unwrap();
        assert_eq!(json["steady_window_s"], serde_json::json!([100.0, 300.0]));
        let p = &json["paired"][1];
        assert_eq!(p["window"], "100-300 s");
        assert_eq!(p["a"], "paper");
        assert_eq!(p["metric"], "ua");
        assert_eq!(p["n"], 3);
        assert!(p["ci95"].as_array().is_some_and(|ci| ci.len() == 2), "{p}");
        let md = table.to_markdown();
        assert!(md.contains("Paired differences a − b"), "{md}");
        assert!(
            md.contains(
                "| a − b | metric | Δ final [95 % CI] | a / b lower, ties | \
                 Δ 100-300 s [95 % CI] | a / b lower, ties |"
            ),
            "{md}"
        );
        // t(0.975, 2) = 4.302653: 10 ± 4.302653 · 10 / √3 = 10 ± 24.84 pp.
        assert!(
            md.contains("| paper − setfleet | UA (pp) | 10.00 [-14.84, 34.84] | 0 / 2, 1 |"),
            "{md}"
        );
        assert!(md.contains("| setfleet − nomap | localisation error (m) | - | - | - | - |"));
    }

    #[test]
    fn seeds_are_named_as_runs_of_consecutive_seeds() {
        assert_eq!(seed_range(&[]), "no seed");
        assert_eq!(seed_range(&[3]), "seed 3");
        assert_eq!(seed_range(&[1, 2, 3, 4, 5]), "seeds 1..=5");
        assert_eq!(seed_range(&[101, 102, 103]), "seeds 101..=103");
        assert_eq!(seed_range(&[1, 2, 5, 7, 8]), "seeds 1..=2, 5, 7..=8");
        assert_eq!(seed_range(&[2, 4]), "seeds 2, 4");
        assert_eq!(
            seed_range(&[1, 3, 5, 7, 9, 11, 12]),
            "seeds 1..=12 with gaps"
        );
    }
}
