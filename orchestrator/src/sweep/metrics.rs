//! The metrics a sweep reports of each run, one record each (`METRICS`): the key of the JSON
//! tables, the label of the Markdown ones, the factor its values are shown with and where a
//! run's value comes from (its `summary.json`, or its `timeseries.csv` over the steady window
//! [`STEADY_WINDOW_S`]).
//!
//! Every table of a sweep reads them here: the sweep's table has a row per metric of `ROWS`
//! ([`super::table`]), an axis table a row per metric, the radio's included ([`super::axis`]),
//! the suite's table a column per metric it picks ([`super::suite`]), and two variants are
//! compared on the metrics of `COMPARED` ([`super::paired`]).

use std::borrow::Cow;

use fleet_observe::observe::StepMetrics;
use fleet_observe::observe::metrics::SetMetrics;
use fleet_observe::results::summary::Summary;

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

/// Where a metric's value of a run comes from.
enum Source {
    /// A value of the run's `summary.json` (`None` where the run has none).
    Summary(fn(&Summary) -> Option<f64>),
    /// The mean of a per-step value (of the step's mean over agents) over the steps of
    /// [`STEADY_WINDOW_S`] that have it; `unit` goes in the label.
    Window {
        step: fn(&SetMetrics) -> Option<f64>,
        unit: &'static str,
    },
}

/// One metric of a run: its key in `table.json`, `suite.json` and `axis.json`, its label in
/// the Markdown tables, the factor its values are shown with, and where a run's value comes
/// from.
pub(super) struct Metric {
    /// Its key in the JSON tables.
    pub(super) key: &'static str,
    /// Its label, without the window of a window metric ([`Metric::label`] adds it).
    label: &'static str,
    /// The factor its values are shown with: 100 for fractions (shown in %), 1 otherwise.
    pub(super) scale: f64,
    /// Where a run's value comes from.
    source: Source,
}

impl Metric {
    /// Its label in the Markdown tables; a window metric's names the window.
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

    /// A run's value: from its summary's values, or from its series of metrics per step (its
    /// `timeseries.csv`) for a window metric.
    fn value(&self, summary: &Summary, series: &[StepMetrics]) -> Option<f64> {
        match self.source {
            Source::Summary(value) => value(summary),
            Source::Window { step, .. } => window_mean(series, step),
        }
    }
}

/// The metric of key `key`, found when the program is compiled (a key no metric has does not
/// compile).
pub(super) const fn metric(key: &str) -> &'static Metric {
    let mut i = 0;
    while i < METRICS.len() {
        if same(METRICS[i].key.as_bytes(), key.as_bytes()) {
            return &METRICS[i];
        }
        i += 1;
    }
    panic!("no metric has this key");
}

/// Whether `a` and `b` are the same bytes (`==` on slices is not available in a `const fn`).
const fn same(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// How many metrics are rows of the sweep's table: all but the radio's, which come last.
const TABLE_ROWS: usize = 17;

/// The rows of the sweep's table (`table.md`, `table.json`), in order.
pub(super) const ROWS: &[Metric] = METRICS.split_at(TABLE_ROWS).0;

/// Every metric, in the order of the tables' rows: those of the sweep's table ([`ROWS`]), then
/// the radio's, which only an axis table shows: what the links lost, measured from the
/// agents' counters, and what the estimates cost (under loss they carry whole sets).
pub(super) static METRICS: [Metric; 20] = [
    Metric {
        key: "ua_final",
        label: "UA, undetected-set area (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.ua_final),
    },
    Metric {
        key: "oa_final",
        label: "OA, undetected and occluded (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.oa_final),
    },
    Metric {
        key: "ua_final_worst",
        label: "UA, worst agent (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.ua_final_worst),
    },
    Metric {
        key: "oa_final_worst",
        label: "OA, worst agent (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.oa_final_worst),
    },
    Metric {
        key: "explored_final",
        label: "explored (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.explored_final),
    },
    Metric {
        key: "target_set_area_mean",
        label: "target-set area, mean over the whole run (%)",
        scale: 100.0,
        source: Source::Summary(|s| s.target_set_area_mean),
    },
    Metric {
        key: "loc_error_mean_m",
        label: "localisation error, mean over the whole run (m)",
        scale: 1.0,
        source: Source::Summary(|s| s.loc_error_mean_m),
    },
    Metric {
        key: "ua_window",
        label: "UA",
        scale: 100.0,
        source: Source::Window {
            step: |m| Some(m.ua),
            unit: "%",
        },
    },
    Metric {
        key: "oa_window",
        label: "OA",
        scale: 100.0,
        source: Source::Window {
            step: |m| Some(m.oa),
            unit: "%",
        },
    },
    Metric {
        key: "target_set_area_window",
        label: "target-set area",
        scale: 100.0,
        source: Source::Window {
            step: |m| m.target_set_area,
            unit: "%",
        },
    },
    Metric {
        key: "loc_error_m_window",
        label: "localisation error",
        scale: 1.0,
        source: Source::Window {
            step: |m| m.loc_error_m,
            unit: "m",
        },
    },
    Metric {
        key: "identified_final",
        label: "identified targets (final)",
        scale: 1.0,
        source: Source::Summary(|s| Some(s.identified_final)),
    },
    Metric {
        key: "violations",
        label: "guarantee violations",
        scale: 1.0,
        source: Source::Summary(|s| Some(s.violations as f64)),
    },
    Metric {
        key: "time_all_identified_s",
        label: "all identified at (s)",
        scale: 1.0,
        source: Source::Summary(|s| s.time_all_identified_s),
    },
    Metric {
        key: "time_ua_below_25_s",
        label: "UA below 25 % at (s)",
        scale: 1.0,
        source: Source::Summary(|s| s.time_ua_below_25_s),
    },
    Metric {
        key: "time_ua_below_15_s",
        label: "UA below 15 % at (s)",
        scale: 1.0,
        source: Source::Summary(|s| s.time_ua_below_15_s),
    },
    Metric {
        key: "real_time_factor",
        label: "real-time factor",
        scale: 1.0,
        source: Source::Summary(|s| Some(s.real_time_factor)),
    },
    // The radio's.
    Metric {
        key: "estimates_lost_share",
        label: "peer estimates lost by the radio (%)",
        scale: 100.0,
        source: Source::Summary(|s| {
            let lost: u64 = s.agents.iter().map(|a| a.estimates_lost).sum();
            let heard = lost + s.agents.iter().map(|a| a.estimates_received).sum::<u64>();
            (heard > 0).then(|| lost as f64 / heard as f64)
        }),
    },
    Metric {
        key: "tokens_lost_share",
        label: "tokens lost by the radio (%)",
        scale: 100.0,
        source: Source::Summary(|s| {
            let lost: u64 = s.agents.iter().map(|a| a.tokens_lost).sum();
            // Every token sent (the observer sees each once) goes to every other agent.
            let sent = s.comms.get("tokens")?.messages;
            let links = sent * u64::from(s.uavs.saturating_sub(1));
            (links > 0).then(|| lost as f64 / links as f64)
        }),
    },
    Metric {
        key: "estimate_kb_per_s",
        label: "estimates sent, kB per simulated s",
        scale: 1.0,
        source: Source::Summary(|s| {
            let bytes = s.comms.get("estimates")?.bytes as f64;
            let sim_s = Some(s.sim_s).filter(|t| *t > 0.0)?;
            Some(bytes / sim_s / 1e3)
        }),
    },
];

/// A metric every two variants are compared on seed by seed ([`super::paired`]); lower is
/// better for each.
pub(super) struct Compared {
    /// Its name in `paired` of `table.json`.
    pub(super) metric: &'static str,
    /// Its name in `table.md`'s comparison, with the unit of a difference.
    pub(super) label: &'static str,
    /// Its two rows: the value of `summary.json`, the mean over the window.
    pub(super) rows: [&'static Metric; 2],
}

impl Compared {
    /// The factor its differences are displayed with: its rows' (100 for fractions, so
    /// percentage points).
    pub(super) fn scale(&self) -> f64 {
        self.rows[0].scale
    }
}

/// The metrics compared, in the order of `paired`.
pub(super) const COMPARED: [Compared; 4] = [
    Compared {
        metric: "ua",
        label: "UA (pp)",
        rows: [metric("ua_final"), metric("ua_window")],
    },
    Compared {
        metric: "oa",
        label: "OA (pp)",
        rows: [metric("oa_final"), metric("oa_window")],
    },
    Compared {
        metric: "target_set_area",
        label: "target-set area (pp)",
        rows: [
            metric("target_set_area_mean"),
            metric("target_set_area_window"),
        ],
    },
    Compared {
        metric: "loc_error_m",
        label: "localisation error (m)",
        rows: [metric("loc_error_mean_m"), metric("loc_error_m_window")],
    },
];

/// A run's value of every metric, in the order of `METRICS` (so its values of the sweep's
/// rows come first): from its summary's values and its series of metrics per step (its
/// `timeseries.csv`).
pub(super) fn run_values(summary: &Summary, series: &[StepMetrics]) -> Vec<Option<f64>> {
    METRICS.iter().map(|m| m.value(summary, series)).collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    fn row(key: &str) -> usize {
        ROWS.iter().position(|r| r.key == key).unwrap()
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
            time_ua_below_25_s: Some(61.5),
            time_ua_below_15_s: Some(140.0),
            real_time_factor: 4.0,
            ..Summary::default()
        };
        let json = serde_json::to_value(&s).unwrap();
        let read: Summary = serde_json::from_value(json.clone()).unwrap();
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
        // A summary of an older release, without a key or with null, reads as the default.
        let sparse = serde_json::json!({"ua_final": null, "violations": 3, "other": "x"});
        let read: Summary = serde_json::from_value(sparse).unwrap();
        assert_eq!(
            (read.ua_final, read.violations, read.oa_final),
            (None, 3, None)
        );
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
        let values = run_values(&Summary::default(), &series);
        assert!((values[row("ua_window")].unwrap() - 0.3).abs() < 1e-12);
        assert_eq!(values[row("loc_error_m_window")], Some(3.0));
        assert_eq!(values[row("target_set_area_window")], None);
        // A run shorter than 100 s has no window mean.
        let short = [step(50.0, 0.5, Some(1.0)), step(99.0, 0.5, Some(1.0))];
        let values = run_values(&Summary::default(), &short);
        assert_eq!(values[row("ua_window")], None);
    }

    #[test]
    fn every_metric_has_its_own_key_and_the_compared_ones_are_rows_of_the_table() {
        for (i, m) in METRICS.iter().enumerate() {
            assert!(
                METRICS[..i].iter().all(|o| o.key != m.key),
                "{} twice",
                m.key
            );
        }
        assert_eq!(METRICS[ROWS.len()].key, "estimates_lost_share");
        for c in &COMPARED {
            for row in c.rows {
                assert!(ROWS.iter().any(|r| std::ptr::eq(r, row)), "{}", row.key);
            }
        }
    }
}
