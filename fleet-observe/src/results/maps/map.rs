//! `map.png`: the fused occupancy elevation map from above (the paper's Fig. 7), unknown cells
//! grey, ground pale green, obstacles coloured by height, with the true building outlines over
//! it for comparison. The coarse map is sampled at pixel centres.

use std::path::Path;

use estimator::occupancy::{OccupancyMap, OemStatus};
use plotters::prelude::*;
use protocol::scenario::Scenario;
use sets::math::Point2;
use world_server::scene::Building;

use super::chart::{
    Area, OUTLINE, OUTSIDE, PANEL, TITLE_PX, build_chart, draw_axes, draw_frame, draw_outlines,
    draw_title, percent, write_picture,
};
use super::legend::{Legend, Swatch};
use super::raster::{Pixels, PlotRaster, rgb};
use crate::pictures::{FONT, viridis};

/// An OEM cell never observed.
const UNKNOWN: RGBColor = RGBColor(236, 236, 236);
/// An OEM cell seen as open ground.
const GROUND: RGBColor = RGBColor(208, 230, 196);
/// Draws the fused occupancy elevation map from above into `path` (PNG): unknown cells grey,
/// ground pale, obstacle cells coloured by their height (colour bar in metres), the true
/// building outlines of the scenario's city on top, the census in the title.
pub fn draw_map(oem: &OccupancyMap, scenario: &Scenario, path: &Path) -> anyhow::Result<()> {
    write_picture(path, "map.png", scenario, |root, buildings| {
        paint_map(root, oem, scenario, buildings).map(drop)
    })
}

/// The map picture on `root`; returns where the plotting area lies.
pub(super) fn paint_map(
    root: &Area<'_>,
    oem: &OccupancyMap,
    scenario: &Scenario,
    buildings: &[Building],
) -> anyhow::Result<PlotRaster> {
    root.fill(&WHITE)?;
    let (unknown, obstacle, ground) = oem.census();
    let total = unknown + obstacle + ground;
    let grid = *oem.grid();
    let title = format!(
        "Fused occupancy elevation map: {:.1} % known (G {ground}, O {obstacle} of {total} \
         cells of {} m)",
        percent((obstacle + ground) as u64, total as u64),
        grid.cell_m
    );
    let (title_area, body) = root.split_vertically(TITLE_PX);
    draw_title(&title_area, &title)?;
    let (panel, legend) = body.split_horizontally(PANEL.0);

    let h = scenario.region.half_extent_m;
    let mut chart = build_chart(&panel, h)?;
    let raster = PlotRaster::of(&chart, h)?;
    let scale = HeightScale::of(oem, scenario);
    let mut pixels = Pixels::new(&raster);
    for py in 0..raster.height {
        let y = raster.y_centre(py);
        for px in 0..raster.width {
            let p = Point2::new(raster.x_centre(px), y);
            let colour = match oem.cell_at(&p) {
                None => OUTSIDE,
                Some(c) => match c.status {
                    OemStatus::Unknown => UNKNOWN,
                    OemStatus::Ground => GROUND,
                    OemStatus::Obstacle => viridis(scale.fraction(f64::from(c.height_m))),
                },
            };
            pixels.put(px, py, rgb(colour));
        }
    }
    raster.blit(root, pixels)?;
    draw_axes(&mut chart)?;
    draw_outlines(&mut chart, buildings)?;
    draw_frame(&mut chart, h)?;

    let (bar_area, keys_area) = legend.split_vertically(PANEL.1 * 11 / 20);
    draw_colour_bar(&bar_area, &scale)?;
    let mut keys = Legend::new(&keys_area);
    keys.heading("Cells")?;
    keys.entry(&Swatch::Fill(UNKNOWN), None, &format!("unknown, {unknown}"))?;
    keys.entry(
        &Swatch::Fill(GROUND),
        None,
        &format!("ground (G), {ground}"),
    )?;
    keys.entry(
        &Swatch::Fill(viridis(0.6)),
        None,
        &format!("obstacle (O), {obstacle}"),
    )?;
    keys.entry(&Swatch::Outline(OUTLINE), None, "true building outline")?;
    Ok(raster)
}

/// The colour scale of obstacle heights: from 0 to the tallest of the scenario's buildings and
/// of the map's obstacles.
struct HeightScale {
    hi: f64,
}

impl HeightScale {
    fn of(oem: &OccupancyMap, scenario: &Scenario) -> HeightScale {
        let seen = oem
            .known_cells()
            .filter(|(_, c)| c.status == OemStatus::Obstacle)
            .map(|(_, c)| f64::from(c.height_m))
            .filter(|h| h.is_finite())
            .fold(0.0_f64, f64::max);
        let hi = seen.max(scenario.region.building_height_m[1]);
        HeightScale {
            hi: if hi > 0.0 { hi } else { 1.0 },
        }
    }

    fn fraction(&self, height: f64) -> f64 {
        height / self.hi
    }
}

/// A vertical viridis bar with the heights in metres.
fn draw_colour_bar(area: &Area<'_>, scale: &HeightScale) -> anyhow::Result<()> {
    const STEPS: usize = 64;
    let mut bar = ChartBuilder::on(area)
        .margin_top(20)
        .margin_bottom(16)
        .margin_left(24)
        .margin_right(190)
        .caption("obstacle height (m)", (FONT, 15))
        .y_label_area_size(40)
        .build_cartesian_2d(0.0..1.0, 0.0..scale.hi)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(8)
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style((FONT, 13))
        .draw()?;
    let step = scale.hi / STEPS as f64;
    bar.draw_series((0..STEPS).map(|i| {
        let (a, b) = (i as f64 * step, (i + 1) as f64 * step);
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            viridis(scale.fraction(0.5 * (a + b))).filled(),
        )
    }))?;
    bar.draw_series(std::iter::once(Rectangle::new(
        [(0.0, 0.0), (1.0, scale.hi)],
        BLACK.stroke_width(1),
    )))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use estimator::occupancy::OemCell;

    use super::super::fixtures::{OutDir, assert_png, colour_at, paint_in_memory, small_scenario};
    use super::*;
    use crate::pictures::register_fonts;

    #[test]
    fn the_map_shows_obstacles_by_height_over_unknown_ground() {
        register_fonts().unwrap();
        let scenario = small_scenario();
        let mut oem = OccupancyMap::new(scenario.oem_grid());
        let grid = *oem.grid();
        for ix in 0..grid.nx / 2 {
            for iy in 0..grid.ny {
                oem.observe_ground((ix, iy));
            }
        }
        let tower = grid.cell_of(&Point2::new(22.0, 12.0)).unwrap();
        let obstacle = OemCell {
            status: OemStatus::Obstacle,
            height_m: 35.0,
        };
        oem.merge_cell(tower, obstacle);
        let centre = grid.cell_centre(tower);

        let (buf, raster) = paint_in_memory(|root| paint_map(root, &oem, &scenario, &[]));
        assert_eq!(raster.width, raster.height, "the plotting area is square");
        let scale = HeightScale::of(&oem, &scenario);
        assert_eq!(
            colour_at(&buf, &raster, centre.x, centre.y),
            rgb(viridis(scale.fraction(35.0)))
        );
        assert_eq!(colour_at(&buf, &raster, -20.0, 0.0), rgb(GROUND));
        assert_eq!(colour_at(&buf, &raster, 20.0, -20.0), rgb(UNKNOWN));

        let dir = OutDir::new("map");
        let path = dir.path.join("map.png");
        draw_map(&oem, &scenario, &path).unwrap();
        assert_png(&path);
    }
}
