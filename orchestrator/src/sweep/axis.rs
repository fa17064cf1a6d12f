//! `fleet sweep --axis KEY=V1,V2,...`: the same sweep at every value of one scenario key (the
//! radio's loss `comms.loss=0,0.1,0.3,0.5`, its latency, its range, or any other key), and
//! how the final metrics change along it.
//!
//! The runs of value `V` go under `KEY=V/<variant>/seed-<n>/`, so each `KEY=V/` directory is
//! a sweep directory of its own, with its `table.json`, `table.md` and `metrics.png` (and
//! `fleet sweep --merge` reads it like any sweep). Beside them the sweep writes:
//!
//! - `axis.json` and `axis.md`: per variant, one row per metric of the sweep's table
//!   ([`super::metrics`], its final values and its means over the steady window) plus the
//!   radio's rows (the share of peer estimates and of tokens the radio lost, measured, and
//!   the estimates' traffic), one column per value, mean ± sample standard deviation over the
//!   seeds; then, per variant, every value compared with the first seed by seed (`paired` in
//!   `axis.json`, the last table of `axis.md`; below);
//! - `axis.png`: UA, localisation error, target-set area and the measured loss against the
//!   value (mean with ±1 sd bars, a line per variant);
//! - `metrics.png`: UA and OA over time per value (and variant), mean and ±1 sd over seeds.
//!
//! **The values compared seed by seed.** The first value listed, `V₁`, is the reference: per
//! variant, every later value `V` is compared with it as [`super::paired`] compares two
//! variants, on the seeds both ran, with `V` as `a` and `V₁` as `b`: the mean of `V − V₁`, its
//! 95 % confidence interval (Student's t), the t statistic, and on how many seeds `V` was
//! lower (`a_better`), `V₁` was (`b_better`) or they tied, on UA, OA, target-set area and
//! localisation error, each final and over the steady window. Unless the key changes them, a
//! seed puts the same cars on the same routes at every value, so the pairs take out that part
//! of the spread over seeds. Each object of `paired` names its `variant`, `value` (`V` as
//! `--axis` writes it), `reference` (`V₁`), `metric` and `window`; the objects come by
//! variant (in column order), then value, metric, and final before window. `axis.md` has a
//! row per variant, value and metric, formatted as `table.md`'s comparisons.
//!
//! A value is applied as the override `KEY=V` after the variant's and the user's `--set`
//! overrides (so it wins over a `--set` of the same key), and checked like any override: a
//! value out of the key's range is refused before anything runs.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::Context as _;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use serde::Serialize;

use super::Shard;
use super::collect::{FoundRuns, MergeConfig, assemble, columns, gather, write_table};
use super::metrics::{METRICS, Metric, metric};
use super::paired::{self, Comparison, PairedMetric, Sides, compare_metrics};
use super::table::{Cell, format_cell, seed_range};
use crate::outcome::Outcome;
use fleet_observe::observe::StepMetrics;
use fleet_observe::pictures::{FONT, palette, short_number};
use fleet_observe::results::curves::draw_bands;
use protocol::variant::Variant;

/// Most values an axis takes.
pub const MAX_AXIS_VALUES: usize = 32;

/// A scenario key and the values a sweep runs it at.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Axis {
    /// The dotted scenario key, e.g. `comms.loss`.
    pub key: String,
    /// Its values, as `--set` writes them, in the table's column order.
    pub values: Vec<String>,
}

/// Why `--axis` could not be read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("--axis {text}: {reason} (expected KEY=V1,V2,... e.g. comms.loss=0,0.1,0.3,0.5)")]
pub struct AxisParseError {
    text: String,
    reason: String,
}

impl FromStr for Axis {
    type Err = AxisParseError;

    fn from_str(text: &str) -> Result<Axis, AxisParseError> {
        let fail = |reason: &str| AxisParseError {
            text: text.to_owned(),
            reason: reason.to_owned(),
        };
        let (key, values) = text.split_once('=').ok_or_else(|| fail("no `=`"))?;
        let key = key.trim();
        let dotted = !key.is_empty()
            && key.split('.').all(|part| {
                !part.is_empty() && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            });
        if !dotted {
            return Err(fail("the key is not a dotted scenario key"));
        }
        let values: Vec<String> = values.split(',').map(|v| v.trim().to_owned()).collect();
        if values.iter().any(String::is_empty) {
            return Err(fail("a value is empty"));
        }
        // A value names a directory: no path separators, no brackets or quotes (an axis takes
        // single numbers, words or booleans).
        let plain = |v: &String| {
            v.chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '+' | '_'))
        };
        if !values.iter().all(plain) {
            return Err(fail(
                "values are single numbers, words or booleans (letters, digits, . - + _)",
            ));
        }
        if values.len() > MAX_AXIS_VALUES {
            return Err(fail(&format!("at most {MAX_AXIS_VALUES} values")));
        }
        for (i, v) in values.iter().enumerate() {
            if values[..i].contains(v) {
                return Err(fail(&format!("{v} is given twice")));
            }
        }
        Ok(Axis {
            key: key.to_owned(),
            values,
        })
    }
}

impl Axis {
    /// The override and the directory of value `i`: `KEY=V`.
    pub fn setting(&self, i: usize) -> String {
        format!("{}={}", self.key, self.values[i])
    }

    /// Value `i` as a number, if every value is one: the x of the picture.
    fn numeric(&self) -> Option<Vec<f64>> {
        self.values
            .iter()
            .map(|v| v.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect()
    }
}

/// `fleet sweep --merge DIR... --axis KEY=V1,...`: each value's runs from `KEY=V/` of every
/// source (a source without it has none), its table under `out/KEY=V/`, and the values
/// compared in `out`.
pub fn merge(config: &MergeConfig, axis: &Axis) -> anyhow::Result<Outcome> {
    let mut levels = Vec::new();
    let mut failed = Vec::new();
    let mut listed = Vec::new();
    for i in 0..axis.values.len() {
        let dirs: Vec<PathBuf> = config
            .sources
            .iter()
            .map(|d| d.join(axis.setting(i)))
            .filter(|d| d.is_dir())
            .collect();
        let (runs, level_failed, level_listed) = gather(&dirs)?;
        levels.push(runs);
        failed.push(level_failed);
        listed.extend(level_listed);
    }
    anyhow::ensure!(
        levels.iter().any(|l| !l.is_empty()),
        "no run found under the merged directories (expected {}=<value>/<variant>/seed-<n>/summary.json)",
        axis.key
    );
    let mut variants: Vec<Variant> = Vec::new();
    for level in &levels {
        for v in columns(level, listed.clone()) {
            if !variants.contains(&v) {
                variants.push(v);
            }
        }
    }
    let write = Levels {
        axis,
        variants: &variants,
        shard: None,
        flag_missing: true,
    };
    let table = write.write(levels, failed, &config.out)?;
    Ok(if table.failed_runs.is_empty() {
        Outcome::Success
    } else {
        Outcome::Failed
    })
}

/// `axis.json`: per variant and value, the statistics over seeds of every row.
#[derive(Clone, Debug, Serialize)]
pub struct AxisTable {
    /// The scenario key.
    pub key: String,
    /// Its values, in column order.
    pub values: Vec<String>,
    /// Seeds run per variant and value.
    pub seeds: Vec<u64>,
    /// Variants.
    pub variants: Vec<Variant>,
    /// `metrics[variant][i][row]`: the cells of value `i`.
    pub metrics: BTreeMap<&'static str, Vec<BTreeMap<&'static str, Cell>>>,
    /// Per variant (in column order), every value after the first compared with the first
    /// seed by seed, on UA, OA, target-set area and localisation error, each by its final
    /// value and by its window mean.
    pub paired: Vec<AxisPaired>,
    /// Runs that failed or were interrupted, as `KEY=V/variant/seed-n`.
    pub failed_runs: Vec<String>,
}

impl AxisTable {
    /// The table of the runs of every value (`levels[i]`: the runs of value `i`).
    pub(super) fn build(
        axis: &Axis,
        variants: &[Variant],
        levels: &[FoundRuns],
        failed_runs: Vec<String>,
    ) -> AxisTable {
        let seeds: Vec<u64> = levels
            .iter()
            .flat_map(|runs| runs.keys().map(|k| k.1))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        let metrics = variants
            .iter()
            .map(|&variant| {
                let columns = levels
                    .iter()
                    .map(|runs| {
                        let run = |seed: &u64| runs.get(&(variant, *seed));
                        let mut cells = BTreeMap::new();
                        for (i, metric) in METRICS.iter().enumerate() {
                            let values = seeds.iter().map(|s| run(s).and_then(|r| r.values[i]));
                            cells.insert(metric.key, Cell::of(values.collect()));
                        }
                        cells
                    })
                    .collect();
                (variant.name(), columns)
            })
            .collect();
        let mut table = AxisTable {
            key: axis.key.clone(),
            values: axis.values.clone(),
            seeds,
            variants: variants.to_vec(),
            metrics,
            paired: Vec::new(),
            failed_runs,
        };
        table.paired = table.compare_values();
        table
    }

    /// Per variant, every value after the first compared with the first on the seeds both
    /// ran: the cells of a row hold every value's runs in the same seed order.
    fn compare_values(&self) -> Vec<AxisPaired> {
        let Some(reference) = self.values.first() else {
            return Vec::new();
        };
        let mut paired = Vec::new();
        for &variant in &self.variants {
            let column =
                |i: usize, key: &str| Some(self.cell(variant.name(), i, key)?.values.clone());
            for (i, value) in self.values.iter().enumerate().skip(1) {
                let metrics = compare_metrics(|key| column(i, key), |key| column(0, key));
                paired.extend(metrics.into_iter().map(|compared| AxisPaired {
                    variant,
                    value: value.clone(),
                    reference: reference.clone(),
                    compared,
                }));
            }
        }
        paired
    }

    /// Per variant, the metrics as rows and the values as columns, in Markdown.
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(
            md,
            "Final metrics and means over {} of simulated time against `{}`, mean ± standard \
             deviation over {} seeds ({}); the set metrics are each agent's own, averaged over \
             agents unless marked worst agent.",
            super::metrics::window_text(),
            self.key,
            self.seeds.len(),
            seed_range(&self.seeds)
        );
        for variant in &self.variants {
            let name = variant.name();
            let _ = writeln!(md, "\n### {name}\n");
            let heads: Vec<String> = self
                .values
                .iter()
                .map(|v| format!("{} = {v}", self.key))
                .collect();
            let _ = writeln!(md, "| metric | {} |", heads.join(" | "));
            let _ = writeln!(md, "|---|{}", "---:|".repeat(heads.len()));
            for metric in &METRICS {
                let cells: Vec<String> = (0..self.values.len())
                    .map(|i| {
                        self.cell(name, i, metric.key)
                            .map_or_else(|| "-".into(), |c| format_cell(c, metric.scale))
                    })
                    .collect();
                let _ = writeln!(md, "| {} | {} |", metric.label(), cells.join(" | "));
            }
        }
        if let Some(reference) = self.values.first() {
            let title = format!(
                "Paired differences V − V₁ between the values of `{}`, per variant: each value V \
                 against the first, V₁ = {reference}",
                self.key
            );
            let sides = Sides {
                title: &title,
                a: "V",
                b: "V₁",
                heads: "variant | V − V₁",
            };
            paired::write_section(&sides, &self.paired, &mut md);
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

    fn cell(&self, variant: &str, i: usize, key: &str) -> Option<&Cell> {
        self.metrics.get(variant)?.get(i)?.get(key)
    }
}

/// A value of the axis compared with the first, for one variant, on one metric: an object of
/// `paired` in `axis.json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AxisPaired {
    /// The variant, run at both values.
    pub variant: Variant,
    /// The value compared, as `--axis` writes it (`a` of the differences).
    pub value: String,
    /// The axis's first value, the reference (`b`).
    pub reference: String,
    /// The metric, its window and the statistics of `value − reference` seed by seed;
    /// `a_better` counts the seeds on which `value` was lower, `b_better` those on which
    /// `reference` was.
    #[serde(flatten)]
    pub compared: PairedMetric,
}

impl Comparison for AxisPaired {
    fn sides(&self) -> String {
        format!(
            "{} | {} − {}",
            self.variant.name(),
            self.value,
            self.reference
        )
    }

    fn compared(&self) -> &PairedMetric {
        &self.compared
    }
}

/// The curves of every value of the axis (and variant), by name, for `metrics.png`.
type AxisCurves = Vec<(String, Vec<Vec<StepMetrics>>)>;

/// How the results of an axis sweep (or of a merge of axis sweeps) are written.
pub(super) struct Levels<'a> {
    /// The key and its values.
    pub axis: &'a Axis,
    /// The variants, in column order.
    pub variants: &'a [Variant],
    /// The share of the sweep the runs are (`--shard`).
    pub shard: Option<Shard>,
    /// Whether a (value, variant, seed) without a run is listed as missing (a merge).
    pub flag_missing: bool,
}

impl Levels<'_> {
    /// Writes each value's table under `out/KEY=V/` (a sweep directory of its own), then the
    /// comparison of the values into `out`; `found[i]` and `failed[i]` are value `i`'s runs
    /// and failed runs.
    pub(super) fn write(
        &self,
        found: Vec<FoundRuns>,
        failed: Vec<Vec<String>>,
        out: &Path,
    ) -> anyhow::Result<AxisTable> {
        let mut table = AxisTable::build(self.axis, self.variants, &found, Vec::new());
        let mut curves = Vec::new();
        for (level, (runs, failed)) in found.into_iter().zip(failed).enumerate() {
            let setting = self.axis.setting(level);
            let (mut level_table, level_curves) =
                assemble(runs, self.variants, failed, self.flag_missing);
            level_table.shard = self.shard.map(|s| s.to_string());
            write_table(&level_table, &level_curves, &out.join(&setting))?;
            let failed = level_table.failed_runs.iter();
            table
                .failed_runs
                .extend(failed.map(|f| format!("{setting}/{f}")));
            for (variant, runs) in level_curves {
                let name = if self.variants.len() == 1 {
                    setting.clone()
                } else {
                    format!("{variant} {setting}")
                };
                curves.push((name, runs));
            }
        }
        write(&table, self.axis, &curves, out)?;
        Ok(table)
    }
}

/// Writes `axis.json`, `axis.md`, `axis.png` and `metrics.png` into `out` and prints the
/// table.
fn write(table: &AxisTable, axis: &Axis, curves: &AxisCurves, out: &Path) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(table)? + "\n";
    std::fs::write(out.join("axis.json"), json).context("cannot write axis.json")?;
    let md = table.to_markdown();
    std::fs::write(out.join("axis.md"), &md).context("cannot write axis.md")?;
    if !table.seeds.is_empty() {
        draw(table, axis, &out.join("axis.png"))?;
    }
    if curves.iter().any(|(_, runs)| !runs.is_empty()) {
        draw_bands(curves, &axis.key, &out.join("metrics.png"))?;
    }
    println!("{md}\nresults in {}", out.display());
    Ok(())
}

/// One panel of `axis.png`: a metric of the table, shown with its scale.
struct Panel {
    caption: &'static str,
    y_desc: &'static str,
    metric: &'static Metric,
    /// Where the legend goes (away from where the curves usually are).
    legend: SeriesLabelPosition,
}

const PANELS: [Panel; 4] = [
    Panel {
        caption: "UA, undetected-set area (final)",
        y_desc: "% of the region",
        metric: metric("ua_final"),
        legend: SeriesLabelPosition::LowerRight,
    },
    Panel {
        caption: "localisation error (mean over the run)",
        y_desc: "m",
        metric: metric("loc_error_mean_m"),
        legend: SeriesLabelPosition::LowerRight,
    },
    Panel {
        caption: "target-set area (mean over the run)",
        y_desc: "% of the region",
        metric: metric("target_set_area_mean"),
        legend: SeriesLabelPosition::LowerRight,
    },
    Panel {
        caption: "peer estimates lost by the radio (measured)",
        y_desc: "%",
        metric: metric("estimates_lost_share"),
        legend: SeriesLabelPosition::UpperLeft,
    },
];

/// `axis.png`: a panel per row of [`PANELS`] against the axis's values, a line per variant
/// through the means, bars of ±1 standard deviation.
fn draw(table: &AxisTable, axis: &Axis, path: &Path) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, (1100, 820)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        &format!(
            "final metrics against {}: mean and ±1 sd over {} seeds ({})",
            axis.key,
            table.seeds.len(),
            seed_range(&table.seeds)
        ),
        (FONT, 19),
    )?;
    for (area, panel) in root.split_evenly((2, 2)).iter().zip(&PANELS) {
        draw_panel(area, panel, table, axis)?;
    }
    root.present()?;
    Ok(())
}

/// Per variant (its index in the table), a panel's points: x, mean and sd, scaled.
type PanelSeries = Vec<(usize, Vec<(f64, f64, f64)>)>;

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    panel: &Panel,
    table: &AxisTable,
    axis: &Axis,
) -> anyhow::Result<()> {
    // Numbers on a numeric axis; otherwise the values one unit apart, named.
    let xs: Vec<f64> = axis
        .numeric()
        .unwrap_or_else(|| (0..axis.values.len()).map(|i| i as f64).collect());
    let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let margin = ((hi - lo) * 0.06).max(0.05);
    let series = panel_series(panel, table, &xs);
    let top = series
        .iter()
        .flat_map(|(_, p)| p.iter().map(|&(_, m, sd)| m + sd))
        .fold(0.0_f64, f64::max);
    let y_top = if top > 0.0 { top * 1.15 } else { 1.0 };
    let mut chart = ChartBuilder::on(area)
        .caption(panel.caption, (FONT, 16))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(lo - margin..hi + margin, 0.0..y_top)?;
    let named = axis.numeric().is_none();
    let names = axis.values.clone();
    chart
        .configure_mesh()
        .x_desc(axis.key.as_str())
        .y_desc(panel.y_desc)
        .x_label_formatter(&|x| {
            if named {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 {
                    return names.get(i as usize).cloned().unwrap_or_default();
                }
                return String::new();
            }
            // Rounded, so that 0.3 reads 0.3 and not 0.30000000000000004.
            format!("{}", (x * 1e6).round() / 1e6)
        })
        .label_style((FONT, 12))
        .draw()?;
    for (v, points) in &series {
        draw_variant(
            &mut chart,
            table.variants[*v].name(),
            palette(*v),
            points,
            margin,
        )?;
    }
    chart
        .configure_series_labels()
        .position(panel.legend.clone())
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 12))
        .draw()?;
    Ok(())
}

/// Each variant's points of `panel` at the axis positions `xs` (a value without a mean and
/// an sd has no point).
fn panel_series(panel: &Panel, table: &AxisTable, xs: &[f64]) -> PanelSeries {
    table
        .variants
        .iter()
        .enumerate()
        .map(|(v, variant)| {
            let points = xs
                .iter()
                .enumerate()
                .filter_map(|(i, &x)| {
                    let cell = table.cell(variant.name(), i, panel.metric.key)?;
                    let (mean, sd) = (cell.mean?, cell.sd?);
                    let scale = panel.metric.scale;
                    Some((x, mean * scale, sd * scale))
                })
                .collect();
            (v, points)
        })
        .collect()
}

/// One variant's line, its ±1 sd bars (with caps `margin / 4` wide), its points and their
/// values.
fn draw_variant(
    chart: &mut ChartContext<'_, BitMapBackend<'_>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    name: &'static str,
    colour: RGBColor,
    points: &[(f64, f64, f64)],
    margin: f64,
) -> anyhow::Result<()> {
    let line: Vec<(f64, f64)> = points.iter().map(|&(x, m, _)| (x, m)).collect();
    chart
        .draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))?
        .label(name)
        .legend(move |(px, py)| {
            PathElement::new(vec![(px, py), (px + 22, py)], colour.stroke_width(2))
        });
    // ±1 sd bars with caps (plotters' error bars are a feature the workspace leaves out).
    let cap = margin * 0.25;
    chart.draw_series(points.iter().flat_map(|&(x, m, sd)| {
        let (lo, hi) = ((m - sd).max(0.0), m + sd);
        [
            vec![(x, lo), (x, hi)],
            vec![(x - cap, lo), (x + cap, lo)],
            vec![(x - cap, hi), (x + cap, hi)],
        ]
        .map(|line| PathElement::new(line, colour.stroke_width(2)))
    }))?;
    chart.draw_series(line.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
    chart.draw_series(points.iter().map(|&(x, m, _)| {
        EmptyElement::at((x, m))
            + Text::new(
                short_number(m),
                (7, -17),
                (FONT, 12).into_font().color(&BLACK),
            )
    }))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::collect::FoundRun;
    use super::super::metrics::run_values;
    use super::super::paired::{Differences, Window};
    use super::*;
    use fleet_observe::results::summary::Summary;

    #[test]
    fn axes_are_parsed_and_bad_ones_named() {
        let a: Axis = "comms.loss=0, 0.1,0.3,0.5".parse().unwrap();
        assert_eq!(a.key, "comms.loss");
        assert_eq!(a.values, ["0", "0.1", "0.3", "0.5"]);
        assert_eq!(a.setting(2), "comms.loss=0.3");
        assert_eq!(a.numeric(), Some(vec![0.0, 0.1, 0.3, 0.5]));
        let words: Axis = "estimator.sets=cells,reach".parse().unwrap();
        assert_eq!(words.numeric(), None);
        for (bad, says) in [
            ("comms.loss", "no `=`"),
            ("=0,1", "dotted scenario key"),
            ("comms..loss=1", "dotted scenario key"),
            ("comms.loss=0,,1", "a value is empty"),
            ("comms.loss=", "a value is empty"),
            ("comms.loss=0.1,0.1", "0.1 is given twice"),
            ("uavs.altitudes_m=[80,90]", "single numbers"),
            ("comms.loss=../x", "single numbers"),
        ] {
            let e = bad.parse::<Axis>().unwrap_err().to_string();
            assert!(e.contains(says) && e.contains("--axis"), "{bad}: {e}");
        }
        let many = format!(
            "seed={}",
            (0..40).map(|i| i.to_string()).collect::<Vec<_>>().join(",")
        );
        assert!(
            many.parse::<Axis>()
                .unwrap_err()
                .to_string()
                .contains("at most")
        );
    }

    fn summary(ua: f64, lost: u64, received: u64) -> Summary {
        let json = serde_json::json!({
            "ua_final": ua,
            "uavs": 2,
            "sim_s": 10.0,
            "agents": [
                {"estimates_lost": lost, "estimates_received": received, "tokens_lost": 1},
                {"estimates_lost": lost, "estimates_received": received, "tokens_lost": 0},
            ],
            "comms": {"tokens": {"messages": 4}, "estimates": {"bytes": 20000}},
        });
        serde_json::from_value(json).unwrap()
    }

    fn run(s: &Summary) -> FoundRun {
        FoundRun {
            values: run_values(s, &[]),
            series: Vec::new(),
            source: std::path::PathBuf::new(),
        }
    }

    #[test]
    fn the_axis_table_has_a_column_per_value_with_the_radio_rows() {
        let axis: Axis = "comms.loss=0,0.5".parse().unwrap();
        let mut none = FoundRuns::new();
        none.insert((Variant::Paper, 1), run(&summary(0.2, 0, 10)));
        none.insert((Variant::Paper, 2), run(&summary(0.4, 0, 10)));
        let mut half = FoundRuns::new();
        half.insert((Variant::Paper, 1), run(&summary(0.5, 5, 5)));
        let table = AxisTable::build(&axis, &[Variant::Paper], &[none, half], vec![]);
        assert_eq!(table.seeds, vec![1, 2]);
        let ua = table.cell("paper", 0, "ua_final").unwrap();
        assert!((ua.mean.unwrap() - 0.3).abs() < 1e-12);
        let lost = table.cell("paper", 1, "estimates_lost_share").unwrap();
        assert_eq!(
            (lost.mean, lost.values.clone()),
            (Some(0.5), vec![Some(0.5), None])
        );
        let tokens = table.cell("paper", 1, "tokens_lost_share").unwrap();
        assert_eq!(tokens.mean, Some(0.25), "1 of 4 tokens x 1 other agent");
        let kb = table.cell("paper", 0, "estimate_kb_per_s").unwrap();
        assert_eq!(kb.mean, Some(2.0));
        let md = table.to_markdown();
        assert!(
            md.contains("| metric | comms.loss = 0 | comms.loss = 0.5 |"),
            "{md}"
        );
        assert!(
            md.contains("| UA, undetected-set area (%) | 30.00 ± 14.14 | 50.00 ± 0.00 |"),
            "{md}"
        );
        assert!(
            md.contains("| peer estimates lost by the radio (%) | 0.00 ± 0.00 | 50.00 ± 0.00 |"),
            "{md}"
        );
    }

    /// A run whose only values are these rows'.
    fn run_of(rows: &[(&str, f64)]) -> FoundRun {
        let mut values = vec![None; METRICS.len()];
        for &(key, value) in rows {
            values[METRICS.iter().position(|m| m.key == key).unwrap()] = Some(value);
        }
        FoundRun {
            values,
            series: Vec::new(),
            source: std::path::PathBuf::new(),
        }
    }

    #[test]
    fn the_axis_compares_every_value_with_the_first_seed_by_seed() {
        let axis: Axis = "comms.loss=0,0.5".parse().unwrap();
        // `paper` on seeds 1..=4: final UA, UA over the window and the localisation error at
        // each value (seed 3 did not run at 0.5); OA has no value anywhere.
        let ua = [
            [Some(0.50), Some(0.40), Some(0.45), Some(0.30)],
            [Some(0.55), Some(0.50), None, Some(0.30)],
        ];
        let ua_window = [
            [Some(0.6), Some(0.5), Some(0.4), Some(0.3)],
            [Some(0.6), Some(0.5), None, Some(0.3)],
        ];
        let error = [
            [Some(10.0), Some(7.0), Some(12.0), Some(5.0)],
            [Some(8.0), Some(7.0), None, Some(9.0)],
        ];
        let levels: Vec<FoundRuns> = (0..2)
            .map(|level| {
                let mut runs = FoundRuns::new();
                for (i, seed) in (1..=4).enumerate() {
                    let (Some(ua), Some(window), Some(error)) =
                        (ua[level][i], ua_window[level][i], error[level][i])
                    else {
                        continue;
                    };
                    let rows = [
                        ("ua_final", ua),
                        ("ua_window", window),
                        ("loc_error_mean_m", error),
                    ];
                    runs.insert((Variant::Paper, seed), run_of(&rows));
                }
                runs
            })
            .collect();
        let table = AxisTable::build(&axis, &[Variant::Paper], &levels, vec![]);
        assert_eq!(table.seeds, vec![1, 2, 3, 4]);
        // One variant, one value after the first, four metrics, two windows each.
        assert_eq!(table.paired.len(), 4 * 2);
        let find = |metric: &str, window: Window| {
            let p = table
                .paired
                .iter()
                .find(|p| (p.compared.metric, p.compared.window) == (metric, window));
            p.unwrap()
        };
        for (metric, window, columns) in [
            ("ua", Window::Final, &ua),
            ("ua", Window::Steady, &ua_window),
            ("loc_error_m", Window::Final, &error),
            ("oa", Window::Final, &[[None; 4]; 2]),
        ] {
            let p = find(metric, window);
            assert_eq!((p.variant, p.value.as_str()), (Variant::Paper, "0.5"));
            assert_eq!(p.reference, "0");
            let expected = Differences::of(&columns[1], &columns[0]);
            assert_eq!(p.compared.differences, expected, "{metric} {window:?}");
        }
        // 0.5 − 0 on seeds 1, 2 and 4: UA 0.05, 0.1, 0 (0.5 lower on none, 0 on two, a tie).
        let d = &find("ua", Window::Final).compared.differences;
        assert_eq!((d.n, d.a_better, d.b_better, d.ties), (3, 0, 2, 1));
        assert!((d.mean.unwrap() - 0.05).abs() < 1e-12 && (d.sd.unwrap() - 0.05).abs() < 1e-12);
        assert_eq!(find("oa", Window::Steady).compared.differences.n, 0);

        let json = serde_json::to_value(&table).unwrap();
        let first = &json["paired"][0];
        for (key, value) in [
            ("variant", "paper"),
            ("value", "0.5"),
            ("reference", "0"),
            ("metric", "ua"),
            ("window", "final"),
        ] {
            assert_eq!(first[key], value, "{first}");
        }
        assert_eq!(first["n"], 3, "{first}");
        assert_eq!(json["paired"][1]["window"], "100-300 s");

        let md = table.to_markdown();
        let section = md.find("Paired differences V − V₁").expect(&md);
        assert!(
            section > md.find("| metric | comms.loss = 0 |").unwrap(),
            "{md}"
        );
        assert!(md.contains("V₁ = 0"), "{md}");
        assert!(
            md.contains(
                "| variant | V − V₁ | metric | Δ final [95 % CI] | V / V₁ lower, ties | \
                 Δ 100-300 s [95 % CI] | V / V₁ lower, ties |\n|---|---|---|---:|---:|---:|---:|"
            ),
            "{md}"
        );
        // t(0.975, 2) = 4.302653: 5 ± 4.302653 · 5 / √3 = 5 ± 12.42 pp.
        assert!(
            md.contains(
                "| paper | 0.5 − 0 | UA (pp) | 5.00 [-7.42, 17.42] | 0 / 2, 1 | \
                 0.00 [0.00, 0.00] | 0 / 0, 3 |"
            ),
            "{md}"
        );
        assert!(
            md.contains("| paper | 0.5 − 0 | OA (pp) | - | - | - | - |"),
            "{md}"
        );

        // A single value has nothing to compare with.
        let one: Axis = "comms.loss=0".parse().unwrap();
        let alone = AxisTable::build(&one, &[Variant::Paper], &levels[..1], vec![]);
        assert!(alone.paired.is_empty());
        assert!(!alone.to_markdown().contains("Paired differences"));
    }

    #[test]
    fn the_axis_picture_is_drawn() {
        fleet_observe::pictures::register_fonts().unwrap();
        let dir = std::env::temp_dir().join(format!("setfleet-axis-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for text in ["comms.loss=0,0.5", "estimator.sets=cells,reach"] {
            let axis: Axis = text.parse().unwrap();
            let mut a = FoundRuns::new();
            a.insert((Variant::Paper, 1), run(&summary(0.2, 0, 10)));
            let mut b = FoundRuns::new();
            b.insert((Variant::Paper, 1), run(&summary(0.4, 5, 5)));
            let table = AxisTable::build(&axis, &[Variant::Paper], &[a, b], vec![]);
            let path = dir.join("axis.png");
            draw(&table, &axis, &path).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            assert!(bytes.starts_with(b"\x89PNG") && bytes.len() > 10_000);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
