//! Pictures of one CVS frame: its labels with the target boxes, and its depth map.

use std::path::Path;

use plotters::prelude::*;
use protocol::frame::{CvsFrame, Label};

use super::{FONT, viridis};

/// Height of the legend band under the image, pixels.
const LEGEND_PX: u32 = 28;

/// Image scale so that small cameras still give readable pictures.
fn scale(frame: &CvsFrame) -> u32 {
    (480 / frame.header.cols.max(1)).clamp(1, 8)
}

/// Colour of a label class.
pub fn label_colour(label: Label) -> RGBColor {
    match label {
        Label::Ground => RGBColor(120, 180, 90),
        Label::Target => RGBColor(220, 30, 30),
        Label::Obstacle => RGBColor(90, 110, 160),
        Label::Unknown => RGBColor(30, 30, 30),
    }
}

/// Writes `labels.png`: a colour per class (G, T, O, U), the boxes of identified targets with
/// their ids, and a legend.
pub fn draw_labels(frame: &CvsFrame, path: &Path) -> anyhow::Result<()> {
    let (rows, cols, s) = (frame.header.rows, frame.header.cols, scale(frame));
    let root = BitMapBackend::new(path, (cols * s, rows * s + LEGEND_PX)).into_drawing_area();
    root.fill(&WHITE)?;
    for r in 0..rows {
        for c in 0..cols {
            let colour = label_colour(frame.label(r, c));
            let (x, y) = ((c * s) as i32, (r * s) as i32);
            root.draw(&Rectangle::new(
                [(x, y), (x + s as i32, y + s as i32)],
                colour.filled(),
            ))?;
        }
    }
    let font = (FONT, 14).into_font().color(&YELLOW);
    for b in frame.boxes() {
        let (x0, y0) = ((b.c0 * s) as i32, (b.r0 * s) as i32);
        let (x1, y1) = ((b.c1 * s) as i32 - 1, (b.r1 * s) as i32 - 1);
        root.draw(&Rectangle::new(
            [(x0, y0), (x1, y1)],
            YELLOW.stroke_width(2),
        ))?;
        // The id goes above the box, or below it when the box touches the top edge.
        let text_y = if y0 >= 16 { y0 - 16 } else { y1 + 2 };
        root.draw(&Text::new(
            format!("{}", b.id),
            (x0 + 2, text_y),
            font.clone(),
        ))?;
    }
    let legend_y = (rows * s) as i32 + 6;
    let text = (FONT, 14).into_font().color(&BLACK);
    let classes = [
        (Label::Ground, "ground"),
        (Label::Target, "target"),
        (Label::Obstacle, "obstacle"),
        (Label::Unknown, "unknown"),
    ];
    for (i, (label, name)) in classes.into_iter().enumerate() {
        let x = 6 + i as i32 * 100;
        root.draw(&Rectangle::new(
            [(x, legend_y), (x + 14, legend_y + 14)],
            label_colour(label).filled(),
        ))?;
        root.draw(&Text::new(name, (x + 18, legend_y), text.clone()))?;
    }
    root.present()?;
    Ok(())
}

/// Writes `depth.png`: the depth map in a colour map (black where nothing was measured) with
/// a scale bar in metres.
pub fn draw_depth(frame: &CvsFrame, path: &Path) -> anyhow::Result<()> {
    const BAR_PX: u32 = 90;
    let (rows, cols, s) = (frame.header.rows, frame.header.cols, scale(frame));
    let n = frame.pixel_count();
    let (lo, hi) = frame.depth[..n]
        .iter()
        .filter(|d| d.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &d| {
            (lo.min(d as f64), hi.max(d as f64))
        });
    let (lo, hi) = if lo <= hi {
        (lo, hi.max(lo + 1e-6))
    } else {
        (0.0, 1.0)
    };
    let height = (rows * s).max(120);
    let root = BitMapBackend::new(path, (cols * s + BAR_PX, height)).into_drawing_area();
    root.fill(&WHITE)?;
    for r in 0..rows {
        for c in 0..cols {
            let d = frame.depth_at(r, c);
            let colour = if d.is_finite() {
                viridis((d as f64 - lo) / (hi - lo))
            } else {
                BLACK
            };
            let (x, y) = ((c * s) as i32, (r * s) as i32);
            root.draw(&Rectangle::new(
                [(x, y), (x + s as i32, y + s as i32)],
                colour.filled(),
            ))?;
        }
    }
    // The scale: far at the top, near at the bottom.
    let (bar_x, top, bottom) = ((cols * s) as i32 + 8, 10_i32, height as i32 - 10);
    for y in top..=bottom {
        let t = (bottom - y) as f64 / (bottom - top).max(1) as f64;
        root.draw(&PathElement::new(
            vec![(bar_x, y), (bar_x + 16, y)],
            viridis(t),
        ))?;
    }
    let font = (FONT, 13).into_font().color(&BLACK);
    for (t, y) in [(1.0, top), (0.5, (top + bottom) / 2), (0.0, bottom - 12)] {
        let metres = lo + t * (hi - lo);
        root.draw(&Text::new(
            format!("{metres:.0} m"),
            (bar_x + 20, y),
            font.clone(),
        ))?;
    }
    root.present()?;
    Ok(())
}
