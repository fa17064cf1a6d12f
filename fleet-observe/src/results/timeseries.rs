//! `timeseries.csv`: one row per measured step with the metrics of `summary.json`. Fractions
//! of the region's area, times in seconds, distances in metres; an empty cell where a metric
//! does not exist at that step (no estimate arrived, nothing identified). No wall-clock
//! column, so the file is reproducible in lockstep.
//!
//! The set metrics come twice: the mean over the agents measured at that step (`explored`,
//! `ua`, ...) and the worst agent (the same names suffixed `_worst`). `identified_any` and
//! `violations` are fleet-wide. When the agents keep `X̄` over windows (`estimator.window_m`)
//! `ua` and `oa` are the fleet's (its `X̄` the intersection of the agents') and `ua_worst`
//! and `oa_worst` the worst agent's over its window (docs/design.md §6, "Under windows").

use std::fmt::Write as _;
use std::path::Path;

use crate::observe::StepMetrics;
use crate::observe::metrics::SetMetrics;

/// The header row.
pub const HEADER: &str = "step,time_s,live_agents,estimates,\
                          explored,ua,oa,target_set_area,loc_error_m,identified,\
                          explored_worst,ua_worst,oa_worst,target_set_area_worst,\
                          loc_error_m_worst,identified_worst,identified_any,violations";

/// The six set-metric cells of one aggregate, empty where missing.
fn set_cells(s: Option<&SetMetrics>) -> String {
    let cell = |v: Option<f64>| v.map_or_else(String::new, |v| v.to_string());
    [
        cell(s.map(|s| s.explored)),
        cell(s.map(|s| s.ua)),
        cell(s.map(|s| s.oa)),
        cell(s.and_then(|s| s.target_set_area)),
        cell(s.and_then(|s| s.loc_error_m)),
        cell(s.map(|s| s.identified)),
    ]
    .join(",")
}

/// The CSV text of a series.
pub fn to_csv(series: &[StepMetrics]) -> String {
    let mut out = String::with_capacity(128 * (series.len() + 1));
    out.push_str(HEADER);
    out.push('\n');
    for m in series {
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{}",
            m.step,
            m.time_s,
            m.live_agents,
            m.estimates,
            set_cells(m.mean.as_ref()),
            set_cells(m.worst.as_ref()),
            m.identified_any,
            m.violations
        );
    }
    out
}

/// Reads a series back from the text [`to_csv`] wrote (e.g. to merge sweeps); an error names
/// the line that does not fit.
pub fn from_csv(text: &str) -> anyhow::Result<Vec<StepMetrics>> {
    let mut lines = text.lines();
    anyhow::ensure!(
        lines.next() == Some(HEADER),
        "not a timeseries.csv: the header differs"
    );
    lines
        .enumerate()
        .map(|(i, line)| {
            parse_row(line).ok_or_else(|| anyhow::anyhow!("line {}: not a timeseries row", i + 2))
        })
        .collect()
}

fn parse_row(line: &str) -> Option<StepMetrics> {
    let cells: Vec<&str> = line.split(',').collect();
    if cells.len() != HEADER.split(',').count() {
        return None;
    }
    let opt = |c: &str| -> Option<Option<f64>> {
        if c.is_empty() {
            Some(None)
        } else {
            c.parse().ok().map(Some)
        }
    };
    let set = |c: &[&str]| -> Option<Option<SetMetrics>> {
        let v: Vec<Option<f64>> = c.iter().map(|c| opt(c)).collect::<Option<_>>()?;
        Some(match (v[0], v[1], v[2], v[5]) {
            (Some(explored), Some(ua), Some(oa), Some(identified)) => Some(SetMetrics {
                explored,
                ua,
                oa,
                target_set_area: v[3],
                loc_error_m: v[4],
                identified,
            }),
            _ => None,
        })
    };
    Some(StepMetrics {
        step: cells[0].parse().ok()?,
        time_s: cells[1].parse().ok()?,
        live_agents: cells[2].parse().ok()?,
        estimates: cells[3].parse().ok()?,
        mean: set(&cells[4..10])?,
        worst: set(&cells[10..16])?,
        identified_any: cells[16].parse().ok()?,
        violations: cells[17].parse().ok()?,
        ..StepMetrics::default()
    })
}

/// Writes the series to `path`.
pub fn write(series: &[StepMetrics], path: &Path) -> anyhow::Result<()> {
    std::fs::write(path, to_csv(series))
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_have_every_column_and_empty_cells_for_missing_metrics() {
        let mean = SetMetrics {
            explored: 0.25,
            ua: 0.5,
            oa: 0.125,
            target_set_area: None,
            loc_error_m: None,
            identified: 0.5,
        };
        let series = [
            StepMetrics {
                step: 0,
                time_s: 0.0,
                live_agents: 2,
                ..StepMetrics::default()
            },
            StepMetrics {
                step: 1,
                time_s: 0.5,
                live_agents: 2,
                estimates: 2,
                mean: Some(mean),
                worst: Some(SetMetrics {
                    ua: 0.75,
                    loc_error_m: Some(2.0),
                    identified: 0.0,
                    ..mean
                }),
                identified_any: 1,
                violations: 1,
                ..StepMetrics::default()
            },
        ];
        let csv = to_csv(&series);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3);
        let columns = HEADER.split(',').count();
        assert!(lines.iter().all(|l| l.split(',').count() == columns));
        assert_eq!(lines[1], "0,0,2,0,,,,,,,,,,,,,0,0");
        assert_eq!(
            lines[2],
            "1,0.5,2,2,0.25,0.5,0.125,,,0.5,0.25,0.75,0.125,,2,0,1,1"
        );
        // What is written reads back to the same text.
        let back = from_csv(&csv).expect("reads back");
        assert_eq!(back.len(), 2);
        assert_eq!(back[1].mean, Some(mean));
        assert_eq!(to_csv(&back), csv);
        assert!(from_csv("step,time_s\n").is_err());
        let broken = csv.replace("0.125,,2", "x,,2");
        assert!(
            from_csv(&broken)
                .unwrap_err()
                .to_string()
                .contains("line 3")
        );
    }
}
