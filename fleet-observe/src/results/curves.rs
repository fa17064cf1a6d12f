//! Metric curves over time: a run's `metrics.png` (the paper's Fig. 8: explored, UA, OA,
//! target-set area and localisation error) and a sweep's `metrics.png` (UA and OA per
//! variant, mean and ±1 standard deviation over seeds). Every curve is of the set metrics'
//! mean over agents ([`StepMetrics::mean`]).

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::observe::StepMetrics;
use crate::observe::metrics::SetMetrics;
use crate::pictures::{FONT, palette};

/// One curve of a panel.
struct Curve {
    name: String,
    colour: RGBColor,
    points: Vec<(f64, f64)>,
    /// Lower and upper edge of a band around the curve, same times as `points`.
    band: Option<Vec<(f64, f64, f64)>>,
}

/// The points of one metric (mean over agents) over a series, skipping the steps where it
/// does not exist.
fn points(series: &[StepMetrics], f: impl Fn(&SetMetrics) -> Option<f64>) -> Vec<(f64, f64)> {
    series
        .iter()
        .filter_map(|m| m.mean.as_ref().and_then(&f).map(|v| (m.time_s, v)))
        .filter(|(_, v)| v.is_finite())
        .collect()
}

/// A y range holding every point of the curves (bands included), from 0, with headroom.
fn y_range(curves: &[Curve]) -> Range<f64> {
    let top = curves
        .iter()
        .flat_map(|c| {
            let band = c.band.iter().flatten().map(|&(_, _, hi)| hi);
            c.points.iter().map(|&(_, y)| y).chain(band)
        })
        .fold(0.0_f64, f64::max);
    0.0..if top > 0.0 { top * 1.08 } else { 1.0 }
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    caption: &str,
    y_desc: &str,
    curves: &[Curve],
    t_max: f64,
    y: Range<f64>,
) -> anyhow::Result<()> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 18))
        .margin(10)
        .x_label_area_size(34)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..t_max.max(1e-9), y)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(y_desc)
        .label_style((FONT, 13))
        .draw()?;
    for c in curves {
        if let Some(band) = &c.band {
            let mut outline: Vec<(f64, f64)> = band.iter().map(|&(t, _, hi)| (t, hi)).collect();
            outline.extend(band.iter().rev().map(|&(t, lo, _)| (t, lo)));
            chart.draw_series(std::iter::once(Polygon::new(
                outline,
                c.colour.mix(0.18).filled(),
            )))?;
        }
        let colour = c.colour;
        chart
            .draw_series(LineSeries::new(c.points.clone(), colour.stroke_width(2)))?
            .label(c.name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 22, y)], colour.stroke_width(2))
            });
    }
    if !curves.is_empty() {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 13))
            .draw()?;
    }
    Ok(())
}

fn t_max(series: &[StepMetrics]) -> f64 {
    series.last().map_or(1.0, |m| m.time_s)
}

/// Writes a run's `metrics.png`: explored, UA and OA (fractions of the region) on top, the
/// mean target-set area in the middle, the mean localisation error below.
pub fn draw_run(series: &[StepMetrics], title: &str, path: &Path) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, (1000, 1000)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, (FONT, 22))?;
    let panels = root.split_evenly((3, 1));
    let t = t_max(series);
    let fractions = vec![
        Curve {
            name: "explored".into(),
            colour: palette(2),
            points: points(series, |s| Some(s.explored)),
            band: None,
        },
        Curve {
            name: "UA (undetected area)".into(),
            colour: palette(0),
            points: points(series, |s| Some(s.ua)),
            band: None,
        },
        Curve {
            name: "OA (undetected in occluded ground)".into(),
            colour: palette(1),
            points: points(series, |s| Some(s.oa)),
            band: None,
        },
    ];
    draw_panel(
        &panels[0],
        "coverage",
        "fraction of the region",
        &fractions,
        t,
        0.0..1.02,
    )?;
    let area = vec![Curve {
        name: "mean target-set area".into(),
        colour: palette(3),
        points: points(series, |s| s.target_set_area),
        band: None,
    }];
    let y = y_range(&area);
    draw_panel(
        &panels[1],
        "identified targets",
        "fraction of the region",
        &area,
        t,
        y,
    )?;
    let error = vec![Curve {
        name: "mean localisation error".into(),
        colour: palette(4),
        points: points(series, |s| s.loc_error_m),
        band: None,
    }];
    let y = y_range(&error);
    draw_panel(&panels[2], "localisation", "error (m)", &error, t, y)?;
    root.present()?;
    Ok(())
}

/// Mean and ±1 standard deviation over runs of one metric (mean over agents), per step
/// index.
pub fn band(
    runs: &[Vec<StepMetrics>],
    f: impl Fn(&SetMetrics) -> f64,
) -> Vec<(f64, f64, f64, f64)> {
    let steps = runs.iter().map(Vec::len).max().unwrap_or(0);
    (0..steps)
        .filter_map(|i| {
            let at: Vec<&StepMetrics> = runs.iter().filter_map(|r| r.get(i)).collect();
            let values: Vec<f64> = at.iter().filter_map(|m| m.mean.as_ref().map(&f)).collect();
            let time = at.first()?.time_s;
            let (mean, sd) = mean_sd(&values)?;
            Some((time, mean, (mean - sd).max(0.0), mean + sd))
        })
        .collect()
}

/// Mean and sample standard deviation (0 for one value); `None` for none.
pub fn mean_sd(values: &[f64]) -> Option<(f64, f64)> {
    if values.is_empty() {
        return None;
    }
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let sd = if values.len() > 1 {
        (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    Some((mean, sd))
}

/// Writes a sweep's `metrics.png`: UA and OA over time per variant, mean over seeds with a
/// ±1 standard deviation band.
pub fn draw_sweep(variants: &[(String, Vec<Vec<StepMetrics>>)], path: &Path) -> anyhow::Result<()> {
    draw_bands(variants, "variant", path)
}

/// UA and OA over time per group of runs (named `what` in the title: a variant, the value of a
/// swept key), mean over the group's runs with a ±1 standard deviation band.
pub fn draw_bands(
    groups: &[(String, Vec<Vec<StepMetrics>>)],
    what: &str,
    path: &Path,
) -> anyhow::Result<()> {
    let root = BitMapBackend::new(path, (1000, 760)).into_drawing_area();
    root.fill(&WHITE)?;
    let seeds = groups.iter().map(|(_, runs)| runs.len()).max().unwrap_or(0);
    let root = root.titled(
        &format!("UA and OA per {what}: mean and ±1 sd over {seeds} seeds"),
        (FONT, 20),
    )?;
    let panels = root.split_evenly((2, 1));
    let t = groups
        .iter()
        .flat_map(|(_, runs)| runs.iter().map(|r| t_max(r)))
        .fold(1e-9, f64::max);
    let metric = |f: fn(&SetMetrics) -> f64| -> Vec<Curve> {
        groups
            .iter()
            .enumerate()
            .map(|(i, (name, runs))| {
                let b = band(runs, f);
                Curve {
                    name: name.clone(),
                    colour: palette(i),
                    points: b.iter().map(|&(t, m, _, _)| (t, m)).collect(),
                    band: Some(b.iter().map(|&(t, _, lo, hi)| (t, lo, hi)).collect()),
                }
            })
            .collect()
    };
    let ua = metric(|s| s.ua);
    draw_panel(
        &panels[0],
        "UA",
        "fraction of the region",
        &ua,
        t,
        0.0..1.02,
    )?;
    let oa = metric(|s| s.oa);
    let y = y_range(&oa);
    draw_panel(&panels[1], "OA", "fraction of the region", &oa, t, y)?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(i: u64, ua: f64) -> StepMetrics {
        StepMetrics {
            step: i,
            time_s: i as f64 * 0.5,
            live_agents: 1,
            estimates: 1,
            mean: Some(SetMetrics {
                ua,
                ..SetMetrics::default()
            }),
            ..StepMetrics::default()
        }
    }

    #[test]
    fn bands_are_mean_and_sample_sd_per_step() {
        let runs = vec![
            vec![step(0, 1.0), step(1, 0.4)],
            vec![step(0, 1.0), step(1, 0.6)],
        ];
        let b = band(&runs, |s| s.ua);
        assert_eq!(b.len(), 2);
        assert_eq!(b[0], (0.0, 1.0, 1.0, 1.0));
        let (t, m, lo, hi) = b[1];
        assert_eq!(t, 0.5);
        assert!((m - 0.5).abs() < 1e-12);
        let sd = 0.02_f64.sqrt();
        assert!((hi - (0.5 + sd)).abs() < 1e-12 && (lo - (0.5 - sd)).abs() < 1e-12);
        assert_eq!(mean_sd(&[]), None);
        assert_eq!(mean_sd(&[3.0]), Some((3.0, 0.0)));
    }
}
