//! The layout both pictures share: a title line, a square chart of the region in metres and a
//! legend panel on the right; the chart's axes, frame and building outlines.

use std::path::Path;

use anyhow::Context as _;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use protocol::scenario::Scenario;
use world_server::World;
use world_server::scene::Building;

use crate::pictures::FONT;

/// Height of the title line, pixels.
pub(super) const TITLE_PX: u32 = 40;
/// Size of the chart panel, pixels.
pub(super) const PANEL: (u32, u32) = (776, 760);
/// Width of the legend panel, pixels.
const LEGEND_W: u32 = 300;
/// Size of either picture.
pub(super) const SIZE: (u32, u32) = (PANEL.0 + LEGEND_W, TITLE_PX + PANEL.1);
/// Chart margin on every side, pixels.
const MARGIN: u32 = 10;
/// Label areas, chosen so the plotting area is square: `PANEL.0 - Y_LABEL == PANEL.1 - X_LABEL`.
const X_LABEL: u32 = 40;
/// See [`X_LABEL`].
const Y_LABEL: u32 = 56;

/// Ground outside the grid, when the view reaches past it.
pub(super) const OUTSIDE: RGBColor = RGBColor(246, 246, 246);
/// Open ground under the set layers.
pub(super) const OPEN: RGBColor = RGBColor(252, 252, 250);
/// Outlines of the true buildings.
pub(super) const OUTLINE: RGBColor = RGBColor(45, 45, 45);

/// A drawing area of a picture.
pub(super) type Area<'b> = DrawingArea<BitMapBackend<'b>, Shift>;
/// The chart of the region on the chart panel.
pub(super) type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Writes the picture `what` of the scenario's city into `path` (PNG): the city is rebuilt
/// from the scenario, and `paint` draws the whole picture over its buildings.
pub(super) fn write_picture(
    path: &Path,
    what: &str,
    scenario: &Scenario,
    paint: impl FnOnce(&Area<'_>, &[Building]) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let city = World::city(scenario).with_context(|| format!("rebuilding the city for {what}"))?;
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    paint(&root, &city.buildings)?;
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// The chart of the square `[-half, half]^2` on `panel`, before anything is drawn on it.
pub(super) fn build_chart<'a, 'b>(panel: &'a Area<'b>, half: f64) -> anyhow::Result<Chart<'a, 'b>> {
    Ok(ChartBuilder::on(panel)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL)
        .y_label_area_size(Y_LABEL)
        .build_cartesian_2d(-half..half, -half..half)?)
}

/// The axes in metres, without a mesh.
pub(super) fn draw_axes(chart: &mut Chart<'_, '_>) -> anyhow::Result<()> {
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x east (m)")
        .y_desc("y north (m)")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style((FONT, 13))
        .draw()?;
    Ok(())
}

/// The true buildings' footprints as thin outlines.
pub(super) fn draw_outlines(
    chart: &mut Chart<'_, '_>,
    buildings: &[Building],
) -> anyhow::Result<()> {
    chart.draw_series(
        (buildings.iter().flat_map(Building::outline))
            .map(|(a, b)| PathElement::new(vec![(a.x, a.y), (b.x, b.y)], OUTLINE.stroke_width(1))),
    )?;
    Ok(())
}

/// A thin frame around the plotting area, over the bitmap's edge.
pub(super) fn draw_frame(chart: &mut Chart<'_, '_>, half: f64) -> anyhow::Result<()> {
    chart.draw_series(std::iter::once(Rectangle::new(
        [(-half, -half), (half, half)],
        BLACK.stroke_width(1),
    )))?;
    Ok(())
}

/// `title`, centred on `area`.
pub(super) fn draw_title(area: &Area<'_>, title: &str) -> anyhow::Result<()> {
    let style = (FONT, 17)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let (w, h) = area.dim_in_pixel();
    area.draw_text(title, &style, (w as i32 / 2, h as i32 / 2))?;
    Ok(())
}

/// `part / whole` in percent (0 for an empty whole).
pub(super) fn percent(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}
