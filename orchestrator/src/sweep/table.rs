//! The sweep's table: the paper's Table I layout, one row per final metric, one column per
//! variant, mean ± sample standard deviation over the seeds (`table.json`, `table.md`).

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::results::curves::mean_sd;
use crate::results::summary::Summary;
use crate::variant::Variant;

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

/// One row of the table: the `table.json` key, the label in `table.md`, the factor to
/// display it with, and where it comes from in a run's summary.
pub(super) struct Row {
    pub(super) key: &'static str,
    pub(super) label: &'static str,
    pub(super) scale: f64,
    value: fn(&Summary) -> Option<f64>,
}

/// How many rows the table has.
pub(super) const ROW_COUNT: usize = ROWS.len();

/// The metrics of the table, in row order.
pub(super) const ROWS: [Row; 11] = [
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
    /// The share of the sweep these runs are (`K/N` of `--shard`), absent for a whole sweep
    /// or a merge.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shard: Option<String>,
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
            shard: None,
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

/// "seeds 1..=5", "seed 3" or "no seed".
pub(super) fn seed_range(seeds: &[u64]) -> String {
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
pub(super) fn row_values_json(summary: &serde_json::Value) -> Vec<Option<f64>> {
    ROWS.iter()
        .map(|row| summary.get(row.key).and_then(serde_json::Value::as_f64))
        .collect()
}

/// "mean ± sd" of a cell, times `scale`, or "-".
pub(super) fn format_cell(cell: &Cell, scale: f64) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
