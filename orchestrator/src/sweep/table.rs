//! The sweep's table: the paper's Table I layout, one row per metric, one column per
//! variant, mean ± sample standard deviation over the seeds (`table.json`, `table.md`), then
//! every two variants compared seed by seed ([`super::paired`]).
//!
//! Most rows are values of each run's `summary.json`, read from its typed [`Summary`](fleet_observe::results::summary::Summary): UA, OA and
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

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use super::metrics::{ROWS, STEADY_WINDOW_S, digits, window_text};
use super::paired::{self, Paired};
use fleet_observe::results::curves::mean_sd;
use protocol::variant::Variant;

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
            "Final metrics (UA, OA and explored at the end of the run; the target-set area \
             and the localisation error as means over the whole run), and four means over {} \
             of simulated time (the paper's steady state), mean ± standard deviation over {} \
             seeds ({}); the set metrics are each agent's own, averaged over agents unless \
             marked worst agent.\n",
            window_text(),
            self.seeds.len(),
            seed_range(&self.seeds)
        );
        let names: Vec<&str> = self.variants.iter().map(|v| v.name()).collect();
        let _ = writeln!(md, "| metric | {} |", names.join(" | "));
        let _ = writeln!(md, "|---|{}", "---:|".repeat(names.len()));
        for row in ROWS {
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
    use crate::sweep::metrics::{METRICS, run_values};
    use fleet_observe::results::summary::Summary;

    /// The row values of a run with these final UA and OA and no time series.
    fn values(ua: f64, oa: Option<f64>) -> Vec<Option<f64>> {
        let summary = Summary {
            ua_final: Some(ua),
            oa_final: oa,
            ..Summary::default()
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
                    vec![None; METRICS.len()],
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

    /// The rows of `table.md` and the keys of `table.json`, in order, byte for byte.
    #[test]
    fn the_table_rows_are_pinned() {
        let table = Table::build(
            vec![1],
            &[(Variant::Paper, vec![values(0.25, None)])],
            vec![],
        );
        let md = table.to_markdown();
        let labels: Vec<&str> = md
            .lines()
            .skip_while(|l| !l.starts_with("|---"))
            .skip(1)
            .take_while(|l| l.starts_with("| "))
            .filter_map(|l| l.split(" | ").next())
            .collect();
        assert_eq!(
            labels,
            [
                "| UA, undetected-set area (%)",
                "| OA, undetected and occluded (%)",
                "| UA, worst agent (%)",
                "| OA, worst agent (%)",
                "| explored (%)",
                "| target-set area, mean over the whole run (%)",
                "| localisation error, mean over the whole run (m)",
                "| UA, mean over 100-300 s (%)",
                "| OA, mean over 100-300 s (%)",
                "| target-set area, mean over 100-300 s (%)",
                "| localisation error, mean over 100-300 s (m)",
                "| identified targets (final)",
                "| guarantee violations",
                "| all identified at (s)",
                "| UA below 25 % at (s)",
                "| UA below 15 % at (s)",
                "| real-time factor",
            ]
        );
        assert!(
            md.contains("| UA, undetected-set area (%) | 25.00 ± 0.00 |\n"),
            "{md}"
        );
        let keys: Vec<&str> = ROWS.iter().map(|r| r.key).collect();
        assert_eq!(
            keys,
            [
                "ua_final",
                "oa_final",
                "ua_final_worst",
                "oa_final_worst",
                "explored_final",
                "target_set_area_mean",
                "loc_error_mean_m",
                "ua_window",
                "oa_window",
                "target_set_area_window",
                "loc_error_m_window",
                "identified_final",
                "violations",
                "time_all_identified_s",
                "time_ua_below_25_s",
                "time_ua_below_15_s",
                "real_time_factor",
            ]
        );
        let written: Vec<&str> = table.metrics["paper"].keys().copied().collect();
        let mut sorted = keys.clone();
        sorted.sort_unstable();
        assert_eq!(written, sorted);
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
