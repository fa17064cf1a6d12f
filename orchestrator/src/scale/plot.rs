//! `scale.png`: four panels against the fleet size (log2 axis): the real-time factor (log
//! axis, with the goal and real time marked), CPU per UAV-step, bytes per UAV per simulated
//! second, and the largest agent's peak memory. Each panel has one line per series (an
//! exchange, `comms.exchange`, and a window, `estimator.window_m`), in the colour of its place in the bench's order ([`palette`] from the
//! second colour on, the first being as red as the goal), named in the panel's legend. A run
//! that failed has no point.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::ScaleConfig;
use super::report::{GOAL_RTF_16, RowStatus, ScaleRow};
use fleet_observe::pictures::{FONT, palette, short_number};

/// One series' points in a panel: (fleet size, value).
struct Line {
    name: String,
    colour: RGBColor,
    points: Vec<(u32, f64)>,
}

/// One panel: its lines and how its y axis reads.
struct Panel {
    caption: &'static str,
    y_desc: &'static str,
    lines: Vec<Line>,
    /// A log10 y axis (for values spanning decades).
    log_y: bool,
    /// Horizontal reference lines: value and name.
    marks: Vec<(f64, String)>,
    /// Where the legend goes: where the lines are not (a falling real-time factor leaves the
    /// upper right free, the figures that grow from a 0-based axis the lower right).
    legend: SeriesLabelPosition,
}

/// Writes the picture of `rows` to `path`.
pub fn draw(rows: &[ScaleRow], config: &ScaleConfig, path: &Path) -> anyhow::Result<()> {
    // One line per series, in the bench's order.
    let lines = |f: &dyn Fn(&ScaleRow) -> Option<f64>| -> Vec<Line> {
        config
            .series
            .iter()
            .enumerate()
            .map(|(i, &series)| Line {
                name: series.label(),
                colour: palette(i + 1),
                points: rows
                    .iter()
                    .filter(|r| r.series == series && r.status == RowStatus::Ok)
                    .filter_map(|r| f(r).filter(|v| v.is_finite()).map(|v| (r.uavs, v)))
                    .collect(),
            })
            .collect()
    };
    let panels = [
        Panel {
            caption: "real-time factor",
            y_desc: "simulated s per wall s",
            lines: lines(&|r| r.real_time_factor().filter(|v| *v > 0.0)),
            log_y: true,
            marks: vec![
                (1.0, "real time".into()),
                (GOAL_RTF_16, format!("goal at 16 UAVs: {GOAL_RTF_16}x")),
            ],
            legend: SeriesLabelPosition::UpperRight,
        },
        Panel {
            caption: "CPU per UAV-step (all processes)",
            y_desc: "ms",
            lines: lines(&|r| r.cpu_ms_per_uav_step),
            log_y: false,
            marks: Vec::new(),
            legend: SeriesLabelPosition::LowerRight,
        },
        Panel {
            caption: "estimates and token, per UAV",
            y_desc: "kB per simulated s",
            lines: lines(&|r| r.bytes_per_uav_s().map(|b| b / 1e3)),
            log_y: false,
            marks: Vec::new(),
            legend: SeriesLabelPosition::LowerRight,
        },
        Panel {
            caption: "peak memory of the largest agent",
            y_desc: "MB",
            lines: lines(&|r| r.memory.agent_max_mb),
            log_y: false,
            marks: Vec::new(),
            legend: SeriesLabelPosition::LowerRight,
        },
    ];
    let root = BitMapBackend::new(path, (1100, 820)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(
        &format!(
            "fleet bench scale: {} s simulated, seed {}, {} variant, lockstep; area per UAV \
             and cars per area fixed",
            config.duration_s,
            config.seed,
            config.variant.name()
        ),
        (FONT, 18),
    )?;
    let sizes: Vec<u32> = rows.iter().map(|r| r.uavs).collect();
    for (area, panel) in root.split_evenly((2, 2)).iter().zip(&panels) {
        draw_panel(area, panel, &sizes)?;
    }
    root.present()?;
    Ok(())
}

/// The x range (log2 of the fleet size) holding every size, with a margin.
fn x_range(sizes: &[u32]) -> std::ops::Range<f64> {
    let logs = sizes.iter().map(|&n| f64::from(n.max(1)).log2());
    let lo = logs.clone().fold(f64::INFINITY, f64::min);
    let hi = logs.fold(f64::NEG_INFINITY, f64::max);
    if lo.is_finite() && hi.is_finite() {
        lo - 0.4..hi + 0.4
    } else {
        -0.4..0.4
    }
}

/// The y range holding the points and the marks: from 0 on a linear axis, a decade-aligned
/// span of log10 values on a log axis.
fn y_range(panel: &Panel) -> std::ops::Range<f64> {
    let values = panel
        .lines
        .iter()
        .flat_map(|l| l.points.iter().map(|p| p.1))
        .chain(panel.marks.iter().map(|m| m.0));
    if panel.log_y {
        let logs: Vec<f64> = values.filter(|v| *v > 0.0).map(f64::log10).collect();
        let lo = logs.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if lo.is_finite() && hi.is_finite() {
            lo.floor()..hi.ceil().max(lo.floor() + 1.0)
        } else {
            -1.0..1.0
        }
    } else {
        let top = values.fold(0.0_f64, f64::max);
        0.0..if top > 0.0 { top * 1.12 } else { 1.0 }
    }
}

/// Whether `value` is at least every line's value at `uavs`.
fn is_highest(panel: &Panel, uavs: u32, value: f64) -> bool {
    panel
        .lines
        .iter()
        .flat_map(|l| &l.points)
        .all(|&(n, v)| n != uavs || v <= value)
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    panel: &Panel,
    sizes: &[u32],
) -> anyhow::Result<()> {
    let y = |v: f64| if panel.log_y { v.log10() } else { v };
    let x = |n: u32| f64::from(n).log2();
    let xs = x_range(sizes);
    let ys = y_range(panel);
    let mut chart = ChartBuilder::on(area)
        .caption(panel.caption, (FONT, 17))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(xs.clone(), ys.clone())?;
    // The x axis is log2 of the fleet size: a label at every power of two, none between.
    let x_labels = (xs.end - xs.start).ceil() as usize * 2 + 1;
    let log_y = panel.log_y;
    chart
        .configure_mesh()
        .x_desc("UAVs")
        .y_desc(panel.y_desc)
        .x_labels(x_labels)
        .x_label_formatter(&|v| {
            let rounded = v.round();
            if (v - rounded).abs() < 1e-6 && rounded >= 0.0 {
                format!("{}", 2f64.powf(rounded))
            } else {
                String::new()
            }
        })
        .y_label_formatter(&|v| {
            let value = if log_y { 10f64.powf(*v) } else { *v };
            short_number(value)
        })
        .label_style((FONT, 13))
        .draw()?;
    for (i, (value, name)) in panel.marks.iter().enumerate() {
        let colour = if i == 0 { BLACK.mix(0.6) } else { RED.mix(0.8) };
        let line = vec![(xs.start, y(*value)), (xs.end, y(*value))];
        chart
            .draw_series(std::iter::once(PathElement::new(
                line,
                colour.stroke_width(1),
            )))?
            .label(name.clone())
            .legend(move |(px, py)| {
                PathElement::new(vec![(px, py), (px + 22, py)], colour.stroke_width(1))
            });
    }
    for line in &panel.lines {
        let points: Vec<(f64, f64)> = line.points.iter().map(|&(n, v)| (x(n), y(v))).collect();
        let colour = line.colour;
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))?
            .label(line.name.clone())
            .legend(move |(px, py)| {
                PathElement::new(vec![(px, py), (px + 22, py)], colour.stroke_width(2))
            });
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
        // Each value beside its point in its line's colour, to the right of the marker: above
        // it where it is the highest at its size, below it elsewhere, so the values of two
        // lines at one size do not cross.
        chart.draw_series(line.points.iter().map(|&(n, v)| {
            let offset = if is_highest(panel, n, v) {
                (7, -17)
            } else {
                (7, 5)
            };
            EmptyElement::at((x(n), y(v)))
                + Text::new(
                    short_number(v),
                    offset,
                    (FONT, 12).into_font().color(&colour),
                )
        }))?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_hold_every_size_and_value() {
        let x = x_range(&[1, 2, 16]);
        assert!(x.start < 0.0 && x.end > 4.0);
        let line = |name: &str, points| Line {
            name: name.to_owned(),
            colour: palette(1),
            points,
        };
        let panel = |log_y, sets: Vec<(u32, f64)>, measurements: Vec<(u32, f64)>| Panel {
            caption: "",
            y_desc: "",
            lines: vec![line("sets", sets), line("measurements", measurements)],
            log_y,
            marks: vec![(2.0, "goal".into())],
            legend: SeriesLabelPosition::UpperRight,
        };
        // 0.08 to 16.5 on a log axis, over both lines: 10^-2 to 10^2.
        assert_eq!(
            y_range(&panel(true, vec![(1, 16.5)], vec![(16, 0.08)])),
            -2.0..2.0
        );
        let linear = panel(false, vec![(1, 10.0), (2, 20.0)], vec![(1, 30.0), (2, 5.0)]);
        let range = y_range(&linear);
        assert_eq!(range.start, 0.0);
        assert!(range.end > 30.0);
        // The highest value at a size is labelled above its point, whichever line it is on.
        assert!(is_highest(&linear, 1, 30.0) && !is_highest(&linear, 1, 10.0));
        assert!(is_highest(&linear, 2, 20.0) && !is_highest(&linear, 2, 5.0));
        assert_eq!(short_number(0.0812), "0.081");
        assert_eq!(short_number(16.49), "16.5");
        assert_eq!(short_number(1234.0), "1234");
    }
}
