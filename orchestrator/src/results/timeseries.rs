//! `timeseries.csv`: one row per measured step with the metrics of `summary.json`. Fractions
//! of the region's area, times in seconds, distances in metres; an empty cell where a metric
//! does not exist at that step (no estimate arrived, nothing identified). No wall-clock
//! column, so the file is reproducible in lockstep.

use std::fmt::Write as _;
use std::path::Path;

use crate::observe::StepMetrics;

/// The header row.
pub const HEADER: &str = "step,time_s,live_agents,estimates,explored,ua,oa,target_set_area,\
                          loc_error_m,identified,violations";

/// The CSV text of a series.
pub fn to_csv(series: &[StepMetrics]) -> String {
    let mut out = String::with_capacity(64 * (series.len() + 1));
    out.push_str(HEADER);
    out.push('\n');
    let cell = |v: Option<f64>| v.map_or_else(String::new, |v| v.to_string());
    for m in series {
        let s = m.sets;
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{}",
            m.step,
            m.time_s,
            m.live_agents,
            m.estimates,
            cell(s.map(|s| s.explored)),
            cell(s.map(|s| s.ua)),
            cell(s.map(|s| s.oa)),
            cell(s.and_then(|s| s.target_set_area)),
            cell(s.and_then(|s| s.loc_error_m)),
            s.map_or(0, |s| s.identified),
            m.violations
        );
    }
    out
}

/// Writes the series to `path`.
pub fn write(series: &[StepMetrics], path: &Path) -> anyhow::Result<()> {
    std::fs::write(path, to_csv(series))
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::metrics::SetMetrics;

    #[test]
    fn rows_have_every_column_and_empty_cells_for_missing_metrics() {
        let series = [
            StepMetrics {
                step: 0,
                time_s: 0.0,
                live_agents: 2,
                estimates: 0,
                sets: None,
                violations: 0,
            },
            StepMetrics {
                step: 1,
                time_s: 0.5,
                live_agents: 2,
                estimates: 2,
                sets: Some(SetMetrics {
                    explored: 0.25,
                    ua: 0.5,
                    oa: 0.125,
                    target_set_area: None,
                    loc_error_m: None,
                    identified: 0,
                }),
                violations: 1,
            },
        ];
        let csv = to_csv(&series);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3);
        let columns = HEADER.split(',').count();
        assert!(lines.iter().all(|l| l.split(',').count() == columns));
        assert_eq!(lines[1], "0,0,2,0,,,,,,0,0");
        assert_eq!(lines[2], "1,0.5,2,2,0.25,0.5,0.125,,,0,1");
    }
}
