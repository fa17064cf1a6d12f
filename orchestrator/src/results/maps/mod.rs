//! `map.png` and `sets.png`: what the fleet knows at the end of a run, seen from above.
//!
//! - [`draw_map`]: the fused occupancy elevation map (the paper's Fig. 7 from above), unknown
//!   cells grey, ground pale green, obstacles coloured by height, with the true building
//!   outlines over it for comparison.
//! - [`draw_sets`]: one agent's final fused sets over the city (the lowest id measured at the
//!   last step; with perfect links every agent holds the same sets but `H̄`): explored
//!   ground, `S^o`, `H̄`, `X̄`, each `X_j`, the true targets and the UAV tracks.
//!
//! Both share one layout: a title line, a square chart of the region in metres and a legend
//! panel on the right. The cell layers are composed per pixel into one bitmap (the set grid
//! has up to a million cells, far more than the chart has pixels) blitted under the vector
//! overlays. A set is drawn at a pixel when any cell the pixel touches belongs to it, so sets
//! smaller than a pixel still show; the coarse map is sampled at pixel centres.

use std::path::Path;

use anyhow::Context as _;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use protocol::grid::GroundGrid;
use protocol::math::Point2;
use protocol::raster::CellSet;
use protocol::scenario::Scenario;
use uav_agent::occupancy::{OccupancyMap, OemStatus};
use world_server::World;
use world_server::scene::Building;

use crate::observe::FinalState;
use crate::pictures::topview::building_shade;
use crate::pictures::{FONT, palette, viridis};

/// Height of the title line, pixels.
const TITLE_PX: u32 = 40;
/// Size of the chart panel, pixels.
const PANEL: (u32, u32) = (776, 760);
/// Width of the legend panel, pixels.
const LEGEND_W: u32 = 300;
/// Size of either picture.
const SIZE: (u32, u32) = (PANEL.0 + LEGEND_W, TITLE_PX + PANEL.1);
/// Chart margin on every side, pixels.
const MARGIN: u32 = 10;
/// Label areas, chosen so the plotting area is square: `PANEL.0 - Y_LABEL == PANEL.1 - X_LABEL`.
const X_LABEL: u32 = 40;
/// See [`X_LABEL`].
const Y_LABEL: u32 = 56;

/// An OEM cell never observed.
const UNKNOWN: RGBColor = RGBColor(236, 236, 236);
/// An OEM cell seen as open ground.
const GROUND: RGBColor = RGBColor(208, 230, 196);
/// Ground outside the grid, when the view reaches past it.
const OUTSIDE: RGBColor = RGBColor(246, 246, 246);
/// Open ground under the set layers.
const OPEN: RGBColor = RGBColor(252, 252, 250);
/// Outlines of the true buildings.
const OUTLINE: RGBColor = RGBColor(45, 45, 45);
/// Explored ground: colour and opacity.
const EXPLORED: (RGBColor, f64) = (RGBColor(150, 205, 150), 0.3);
/// `S^o`: colour and opacity.
const OBSTACLE_NEIGHBOURHOOD: (RGBColor, f64) = (RGBColor(55, 65, 120), 0.4);
/// `X̄`: colour and opacity.
const UNDETECTED: (RGBColor, f64) = (RGBColor(255, 185, 0), 0.45);
/// Opacity of a target set `X_j` (its colour is the target's palette colour).
const TARGET_ALPHA: f64 = 0.45;
/// Hatch lines of `H̄`: colour, opacity and period in pixels.
const UNSEEN_HATCH: (RGBColor, f64, u32) = (RGBColor(40, 40, 40), 0.75, 7);
/// Legend rows listed per kind (target sets, UAVs) before the rest are summarised.
const LEGEND_MAX_ROWS: usize = 10;

type Area<'b> = DrawingArea<BitMapBackend<'b>, Shift>;
type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws the fused occupancy elevation map from above into `path` (PNG): unknown cells grey,
/// ground pale, obstacle cells coloured by their height (colour bar in metres), the true
/// building outlines of the scenario's city on top, the census in the title.
pub fn draw_map(oem: &OccupancyMap, scenario: &Scenario, path: &Path) -> anyhow::Result<()> {
    let world = World::new(scenario).context("rebuilding the city for map.png")?;
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    paint_map(&root, oem, scenario, &world.scene().buildings)?;
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Draws one agent's final fused sets over the city into `path` (PNG): building footprints, explored
/// ground, `S^o`, `H̄` (hatched), `X̄`, each `X_j` in its target's colour, the true targets
/// and each UAV's track (`tracks[i]`: UAV `i`'s ground positions) with its final position.
/// Fails when the sets do not live on the scenario's grid.
pub fn draw_sets(
    state: &FinalState,
    tracks: &[Vec<[f64; 2]>],
    scenario: &Scenario,
    path: &Path,
) -> anyhow::Result<()> {
    check_grid(state, scenario)?;
    let world = World::new(scenario).context("rebuilding the city for sets.png")?;
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    paint_sets(&root, state, tracks, scenario, &world.scene().buildings)?;
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// The map picture on `root`; returns where the plotting area lies.
fn paint_map(
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

/// The sets picture on `root`; returns where the plotting area lies.
fn paint_sets(
    root: &Area<'_>,
    state: &FinalState,
    tracks: &[Vec<[f64; 2]>],
    scenario: &Scenario,
    buildings: &[Building],
) -> anyhow::Result<PlotRaster> {
    let grid = scenario.grid();
    let sets = &state.sets;
    root.fill(&WHITE)?;
    let cells = grid.cell_count() as u64;
    let truth_ids: Vec<u32> = state.targets.iter().map(|t| t.id).collect();
    let found = truth_ids
        .iter()
        .filter(|id| sets.targets.contains_key(id))
        .count();
    let title = format!(
        "UAV {}'s final sets at t = {:.1} s (step {}): {found} of {} targets identified, \
         areas in % of the region",
        state.uav,
        state.time_s,
        state.step,
        truth_ids.len()
    );
    let (title_area, body) = root.split_vertically(TITLE_PX);
    draw_title(&title_area, &title)?;
    let (panel, legend) = body.split_horizontally(PANEL.0);

    // The view holds the region and anything drawn outside it.
    let reach = tracks
        .iter()
        .flatten()
        .copied()
        .chain(state.targets.iter().map(|t| t.ground))
        .flat_map(|[x, y]| [x.abs(), y.abs()])
        .filter(|v| v.is_finite())
        .fold(0.0_f64, f64::max);
    let h = scenario.region.half_extent_m;
    let half = if reach > h { reach * 1.03 } else { h };
    let mut chart = build_chart(&panel, half)?;
    let raster = PlotRaster::of(&chart, half)?;

    let [lo, hi] = scenario.region.building_height_m;
    let mut pixels = Pixels::new(&raster);
    let bounds = grid.bounds();
    for py in 0..raster.height {
        let y = raster.y_centre(py);
        for px in 0..raster.width {
            let p = Point2::new(raster.x_centre(px), y);
            let colour = if bounds.contains(&p) { OPEN } else { OUTSIDE };
            pixels.put(px, py, rgb(colour));
        }
    }
    for b in buildings {
        pixels.fill_rect(&raster, b, rgb(building_shade(b.height, lo, hi)));
    }

    let cols = raster.cell_columns(&grid);
    let rows = raster.cell_rows(&grid);
    let explored = mask(&sets.explored, &cols, &rows);
    let neighbourhood = mask(&sets.obstacle_free, &cols, &rows);
    let undetected = mask(&sets.undetected, &cols, &rows);
    let unseen = mask(&sets.unseen, &cols, &rows);
    let targets: Vec<(RGBColor, Vec<bool>)> = sets
        .targets
        .iter()
        .map(|(&id, set)| (target_colour(id), mask(set, &cols, &rows)))
        .collect();
    let (w, h_px) = (raster.width as usize, raster.height as usize);
    for py in 0..h_px {
        for px in 0..w {
            let i = py * w + px;
            let mut c = pixels.get(px as u32, py as u32);
            if explored[i] {
                c = blend(c, EXPLORED.0, EXPLORED.1);
            }
            if neighbourhood[i] {
                c = blend(c, OBSTACLE_NEIGHBOURHOOD.0, OBSTACLE_NEIGHBOURHOOD.1);
            }
            if undetected[i] {
                c = blend(c, UNDETECTED.0, UNDETECTED.1);
            }
            for (colour, m) in &targets {
                if m[i] {
                    c = if is_edge(m, w, h_px, px, py) {
                        rgb(*colour)
                    } else {
                        blend(c, *colour, TARGET_ALPHA)
                    };
                }
            }
            if unseen[i] && (px + py) % UNSEEN_HATCH.2 as usize == 0 {
                c = blend(c, UNSEEN_HATCH.0, UNSEEN_HATCH.1);
            }
            pixels.put(px as u32, py as u32, c);
        }
    }
    raster.blit(root, pixels)?;
    draw_axes(&mut chart)?;
    draw_outlines(&mut chart, buildings)?;

    let label = |text: String, at: (i32, i32), pos: Pos| {
        let style = (FONT, 14).into_font().color(&BLACK).pos(pos);
        root.draw(&Text::new(text, at, style))
    };
    for (i, track) in tracks.iter().enumerate() {
        let colour = palette(i);
        let points: Vec<(i32, i32)> = track
            .iter()
            .filter(|[x, y]| x.is_finite() && y.is_finite())
            .map(|&[x, y]| chart.backend_coord(&(x, y)))
            .collect();
        let Some(&(x, y)) = points.last() else {
            continue;
        };
        thick_path(root, &points, colour)?;
        uav_marker(root, (x, y), colour)?;
        label(
            format!("UAV {i}"),
            (x + 8, y - 4),
            Pos::new(HPos::Left, VPos::Bottom),
        )?;
    }
    for t in &state.targets {
        let [x, y] = t.ground;
        if !(x.is_finite() && y.is_finite()) {
            continue;
        }
        let (x, y) = chart.backend_coord(&(x, y));
        target_marker(root, (x, y), target_colour(t.id))?;
        label(
            format!("T{}", t.id),
            (x + 7, y - 5),
            Pos::new(HPos::Left, VPos::Bottom),
        )?;
    }
    draw_frame(&mut chart, half)?;

    let share = |set: &CellSet| format!("{:.1} %", percent(set.count(), cells));
    let mut keys = Legend::new(&legend);
    keys.heading("Layers")?;
    keys.entry(
        &Swatch::Building(building_shade(0.5 * (lo + hi), lo, hi)),
        None,
        "building",
    )?;
    keys.entry(
        &Swatch::Fill(blend_rgb(OPEN, EXPLORED.0, EXPLORED.1)),
        None,
        &format!("explored ground, {}", share(&sets.explored)),
    )?;
    keys.entry(
        &Swatch::Fill(blend_rgb(
            OPEN,
            OBSTACLE_NEIGHBOURHOOD.0,
            OBSTACLE_NEIGHBOURHOOD.1,
        )),
        Some(Symbol::Sup("S", "o")),
        &format!("obstacle neighbourhoods, {}", share(&sets.obstacle_free)),
    )?;
    keys.entry(
        &Swatch::Hatch,
        Some(Symbol::Bar("H")),
        &format!("unseen ground, {}", share(&sets.unseen)),
    )?;
    keys.entry(
        &Swatch::Fill(blend_rgb(OPEN, UNDETECTED.0, UNDETECTED.1)),
        Some(Symbol::Bar("X")),
        &format!("undetected set, {}", share(&sets.undetected)),
    )?;
    keys.gap();
    keys.heading("Targets")?;
    if sets.targets.is_empty() {
        keys.text("no target identified")?;
    }
    for (&id, set) in sets.targets.iter().take(LEGEND_MAX_ROWS) {
        let colour = target_colour(id);
        let sub = id.to_string();
        keys.entry(
            &Swatch::Edged(blend_rgb(OPEN, colour, TARGET_ALPHA), colour),
            Some(Symbol::Sub("X", &sub)),
            &format!("set of T{id}, {:.0} m\u{b2}", set.area(&grid)),
        )?;
    }
    if sets.targets.len() > LEGEND_MAX_ROWS {
        keys.text(&format!(
            "and {} more",
            sets.targets.len() - LEGEND_MAX_ROWS
        ))?;
    }
    keys.entry(&Swatch::Target, None, "true target T<id>")?;
    keys.gap();
    keys.heading("UAVs")?;
    for i in 0..tracks.len().min(LEGEND_MAX_ROWS) {
        keys.entry(
            &Swatch::Track(palette(i)),
            None,
            &format!("UAV {i}: track, last position"),
        )?;
    }
    if tracks.len() > LEGEND_MAX_ROWS {
        keys.text(&format!("and {} more", tracks.len() - LEGEND_MAX_ROWS))?;
    }
    Ok(raster)
}

/// Fails unless every set of `state` lives on the scenario's grid.
fn check_grid(state: &FinalState, scenario: &Scenario) -> anyhow::Result<()> {
    let grid = scenario.grid();
    let sets = &state.sets;
    let named = [
        ("X\u{304}", &sets.undetected),
        ("S^o", &sets.obstacle_free),
        ("explored", &sets.explored),
        ("H\u{304}", &sets.unseen),
    ];
    let targets = sets.targets.values().map(|s| ("X_j", s));
    for (name, set) in named.into_iter().chain(targets) {
        anyhow::ensure!(
            set.nx() == grid.nx && set.ny() == grid.ny,
            "the {name} set is on a {}x{} grid, the scenario's grid is {}x{}",
            set.nx(),
            set.ny(),
            grid.nx,
            grid.ny
        );
    }
    Ok(())
}

/// A two-pixel polyline through pixel points (four one-pixel passes: plotters' thick strokes
/// leave holes in steep segments).
fn thick_path(area: &Area<'_>, points: &[(i32, i32)], colour: RGBColor) -> anyhow::Result<()> {
    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        let shifted: Vec<(i32, i32)> = points.iter().map(|&(x, y)| (x + dx, y + dy)).collect();
        area.draw(&PathElement::new(shifted, colour.stroke_width(1)))?;
    }
    Ok(())
}

/// A UAV's last position: a triangle in its colour.
fn uav_marker(area: &Area<'_>, at: (i32, i32), colour: RGBColor) -> anyhow::Result<()> {
    area.draw(&TriangleMarker::new(at, 8, colour.filled()))?;
    area.draw(&TriangleMarker::new(at, 8, BLACK.stroke_width(1)))?;
    Ok(())
}

/// A true target: a disc in its colour, ringed black.
fn target_marker(area: &Area<'_>, at: (i32, i32), colour: RGBColor) -> anyhow::Result<()> {
    area.draw(&Circle::new(at, 5, colour.filled()))?;
    area.draw(&Circle::new(at, 5, BLACK.stroke_width(2)))?;
    Ok(())
}

/// The colour of target `id` (its set and its marker).
fn target_colour(id: u32) -> RGBColor {
    palette(id as usize)
}

/// `part / whole` in percent (0 for an empty whole).
fn percent(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

fn rgb(c: RGBColor) -> [u8; 3] {
    [c.0, c.1, c.2]
}

/// `over` at opacity `alpha` on `under`.
fn blend(under: [u8; 3], over: RGBColor, alpha: f64) -> [u8; 3] {
    let mix = |u: u8, o: u8| (f64::from(u) + (f64::from(o) - f64::from(u)) * alpha).round() as u8;
    [
        mix(under[0], over.0),
        mix(under[1], over.1),
        mix(under[2], over.2),
    ]
}

fn blend_rgb(under: RGBColor, over: RGBColor, alpha: f64) -> RGBColor {
    let [r, g, b] = blend(rgb(under), over, alpha);
    RGBColor(r, g, b)
}

/// Whether pixel `(px, py)` of `mask` has a 4-neighbour outside it (or lies on the border).
fn is_edge(mask: &[bool], w: usize, h: usize, px: usize, py: usize) -> bool {
    px == 0
        || py == 0
        || px + 1 == w
        || py + 1 == h
        || !mask[py * w + px - 1]
        || !mask[py * w + px + 1]
        || !mask[(py - 1) * w + px]
        || !mask[(py + 1) * w + px]
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

/// The chart of the square `[-half, half]^2` on `panel`, before anything is drawn on it.
fn build_chart<'a, 'b>(panel: &'a Area<'b>, half: f64) -> anyhow::Result<Chart<'a, 'b>> {
    Ok(ChartBuilder::on(panel)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL)
        .y_label_area_size(Y_LABEL)
        .build_cartesian_2d(-half..half, -half..half)?)
}

fn draw_axes(chart: &mut Chart<'_, '_>) -> anyhow::Result<()> {
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

/// A thin frame around the plotting area, over the bitmap's edge.
/// The true buildings' footprints as thin outlines.
fn draw_outlines(chart: &mut Chart<'_, '_>, buildings: &[Building]) -> anyhow::Result<()> {
    chart.draw_series(buildings.iter().map(|b| {
        Rectangle::new(
            [(b.min.x, b.min.y), (b.max.x, b.max.y)],
            OUTLINE.stroke_width(1),
        )
    }))?;
    Ok(())
}

fn draw_frame(chart: &mut Chart<'_, '_>, half: f64) -> anyhow::Result<()> {
    chart.draw_series(std::iter::once(Rectangle::new(
        [(-half, -half), (half, half)],
        BLACK.stroke_width(1),
    )))?;
    Ok(())
}

fn draw_title(area: &Area<'_>, title: &str) -> anyhow::Result<()> {
    let style = (FONT, 17)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let (w, h) = area.dim_in_pixel();
    area.draw_text(title, &style, (w as i32 / 2, h as i32 / 2))?;
    Ok(())
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

/// Where the chart's plotting area lies in the picture and what ground each pixel covers.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PlotRaster {
    /// Picture column of the area's first pixel.
    left: i32,
    /// Picture row of the area's first pixel.
    top: i32,
    width: u32,
    height: u32,
    /// West edge of the view, metres.
    x_lo: f64,
    /// North edge of the view, metres.
    y_hi: f64,
    /// Metres per pixel along x.
    mx: f64,
    /// Metres per pixel along y.
    my: f64,
}

impl PlotRaster {
    fn of(chart: &Chart<'_, '_>, half: f64) -> anyhow::Result<PlotRaster> {
        let (left, bottom) = chart.backend_coord(&(-half, -half));
        let (right, top) = chart.backend_coord(&(half, half));
        let width = u32::try_from(right - left).ok().filter(|&w| w > 0);
        let height = u32::try_from(bottom - top).ok().filter(|&h| h > 0);
        let (Some(width), Some(height)) = (width, height) else {
            anyhow::bail!("the chart's plotting area is empty");
        };
        Ok(PlotRaster {
            left,
            top,
            width,
            height,
            x_lo: -half,
            y_hi: half,
            mx: 2.0 * half / f64::from(width),
            my: 2.0 * half / f64::from(height),
        })
    }

    fn x_centre(&self, px: u32) -> f64 {
        self.x_lo + (f64::from(px) + 0.5) * self.mx
    }

    fn y_centre(&self, py: u32) -> f64 {
        self.y_hi - (f64::from(py) + 0.5) * self.my
    }

    /// The pixel (from the area's top-left corner) showing ground point `(x, y)`.
    #[cfg(test)]
    fn pixel_of(&self, x: f64, y: f64) -> Option<(u32, u32)> {
        let px = ((x - self.x_lo) / self.mx).floor();
        let py = ((self.y_hi - y) / self.my).floor();
        (px >= 0.0 && py >= 0.0 && px < f64::from(self.width) && py < f64::from(self.height))
            .then_some((px as u32, py as u32))
    }

    /// The range of pixel columns whose centres lie in `[lo, hi]` metres, if any.
    fn columns_in(&self, lo: f64, hi: f64) -> Option<(u32, u32)> {
        let a = ((lo - self.x_lo) / self.mx - 0.5).ceil().max(0.0);
        let b = ((hi - self.x_lo) / self.mx - 0.5)
            .floor()
            .min(f64::from(self.width) - 1.0);
        (a <= b).then_some((a as u32, b as u32))
    }

    /// The range of pixel rows whose centres lie in `[lo, hi]` metres, if any.
    fn rows_in(&self, lo: f64, hi: f64) -> Option<(u32, u32)> {
        let a = ((self.y_hi - hi) / self.my - 0.5).ceil().max(0.0);
        let b = ((self.y_hi - lo) / self.my - 0.5)
            .floor()
            .min(f64::from(self.height) - 1.0);
        (a <= b).then_some((a as u32, b as u32))
    }

    /// For each pixel column, the grid columns it touches.
    fn cell_columns(&self, grid: &GroundGrid) -> Vec<Option<(u32, u32)>> {
        (0..self.width)
            .map(|px| {
                let lo = self.x_lo + f64::from(px) * self.mx;
                cells_spanned(grid.origin.x, grid.cell_m, grid.nx, lo, lo + self.mx)
            })
            .collect()
    }

    /// For each pixel row (from the top), the grid rows it touches.
    fn cell_rows(&self, grid: &GroundGrid) -> Vec<Option<(u32, u32)>> {
        (0..self.height)
            .map(|py| {
                let hi = self.y_hi - f64::from(py) * self.my;
                cells_spanned(grid.origin.y, grid.cell_m, grid.ny, hi - self.my, hi)
            })
            .collect()
    }

    /// Copies `pixels` onto the plotting area of `root`.
    fn blit(&self, root: &Area<'_>, pixels: Pixels) -> anyhow::Result<()> {
        let image = BitMapElement::<(i32, i32)>::with_owned_buffer(
            (self.left, self.top),
            (self.width, self.height),
            pixels.rgb,
        )
        .context("the cell bitmap does not fit the plotting area")?;
        root.draw(&image)?;
        Ok(())
    }
}

/// The cells along one axis (origin `origin`, side `d`, `n` cells) whose extent meets the
/// span `[lo, hi]` with more than a point, clamped to the grid; `None` when the span misses it.
fn cells_spanned(origin: f64, d: f64, n: u32, lo: f64, hi: f64) -> Option<(u32, u32)> {
    let k0 = ((lo - origin) / d).floor();
    let k1 = (((hi - origin) / d).ceil() - 1.0).max(k0);
    if !(k0.is_finite() && k1.is_finite()) || k1 < 0.0 || k0 >= f64::from(n) {
        return None;
    }
    Some((k0.max(0.0) as u32, k1.min(f64::from(n) - 1.0) as u32))
}

/// Which pixels show `set`: those touching at least one of its cells.
fn mask(set: &CellSet, cols: &[Option<(u32, u32)>], rows: &[Option<(u32, u32)>]) -> Vec<bool> {
    let w = cols.len();
    let mut out = vec![false; w * rows.len()];
    let Some(bbox) = set.bounding_box() else {
        return out;
    };
    for (line, row) in out.chunks_exact_mut(w).zip(rows) {
        let Some((r0, r1)) = *row else {
            continue;
        };
        if r1 < bbox.y0 || r0 > bbox.y1 {
            continue;
        }
        for (pixel, col) in line.iter_mut().zip(cols) {
            let Some((c0, c1)) = *col else {
                continue;
            };
            if c1 < bbox.x0 || c0 > bbox.x1 {
                continue;
            }
            *pixel = (r0..=r1).any(|iy| (c0..=c1).any(|ix| set.contains((ix, iy))));
        }
    }
    out
}

/// The RGB bitmap of the plotting area, row-major from the top-left pixel.
struct Pixels {
    width: u32,
    rgb: Vec<u8>,
}

impl Pixels {
    fn new(raster: &PlotRaster) -> Pixels {
        Pixels {
            width: raster.width,
            rgb: vec![255; raster.width as usize * raster.height as usize * 3],
        }
    }

    fn index(&self, px: u32, py: u32) -> usize {
        (py as usize * self.width as usize + px as usize) * 3
    }

    fn get(&self, px: u32, py: u32) -> [u8; 3] {
        let i = self.index(px, py);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn put(&mut self, px: u32, py: u32, c: [u8; 3]) {
        let i = self.index(px, py);
        self.rgb[i..i + 3].copy_from_slice(&c);
    }

    /// Paints the pixels whose centres lie on building `b`'s footprint.
    fn fill_rect(&mut self, raster: &PlotRaster, b: &Building, c: [u8; 3]) {
        let (Some((x0, x1)), Some((y0, y1))) = (
            raster.columns_in(b.min.x, b.max.x),
            raster.rows_in(b.min.y, b.max.y),
        ) else {
            return;
        };
        for py in y0..=y1 {
            for px in x0..=x1 {
                self.put(px, py, c);
            }
        }
    }
}

/// What a legend row shows left of its text.
enum Swatch {
    /// A filled box.
    Fill(RGBColor),
    /// A filled box with a building outline.
    Building(RGBColor),
    /// A filled box with an edge of another colour.
    Edged(RGBColor, RGBColor),
    /// An empty box.
    Outline(RGBColor),
    /// The hatch of `H̄` on open ground.
    Hatch,
    /// A true target's marker.
    Target,
    /// A track ending in a UAV marker.
    Track(RGBColor),
}

/// A set's symbol as the paper writes it, drawn before a legend row's text.
#[derive(Clone, Copy, Debug)]
enum Symbol<'s> {
    /// A letter with a bar over it (`X̄`, `H̄`).
    Bar(&'s str),
    /// A letter with a superscript (`S^o`).
    Sup(&'s str, &'s str),
    /// A letter with a subscript (`X_j`).
    Sub(&'s str, &'s str),
}

/// Rows of swatches and text down a legend panel.
struct Legend<'a, 'b> {
    area: &'a Area<'b>,
    y: i32,
}

impl<'a, 'b> Legend<'a, 'b> {
    const ROW_PX: i32 = 22;
    const LEFT: i32 = 14;
    const SWATCH: (i32, i32) = (26, 14);

    fn new(area: &'a Area<'b>) -> Legend<'a, 'b> {
        Legend { area, y: 16 }
    }

    fn text_style(size: u32) -> TextStyle<'static> {
        (FONT, size)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Left, VPos::Center))
    }

    fn heading(&mut self, text: &str) -> anyhow::Result<()> {
        self.area.draw_text(
            text,
            &(FONT, 15)
                .into_font()
                .style(FontStyle::Bold)
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Center)),
            (Self::LEFT, self.y),
        )?;
        self.y += Self::ROW_PX;
        Ok(())
    }

    fn gap(&mut self) {
        self.y += Self::ROW_PX / 2;
    }

    fn text(&mut self, text: &str) -> anyhow::Result<()> {
        self.area.draw_text(
            text,
            &Self::text_style(13),
            (Self::LEFT + Self::SWATCH.0 + 10, self.y),
        )?;
        self.y += Self::ROW_PX;
        Ok(())
    }

    fn entry(
        &mut self,
        swatch: &Swatch,
        symbol: Option<Symbol<'_>>,
        text: &str,
    ) -> anyhow::Result<()> {
        let (x0, y0) = (Self::LEFT, self.y - Self::SWATCH.1 / 2);
        let (x1, y1) = (x0 + Self::SWATCH.0, y0 + Self::SWATCH.1);
        let rect = [(x0, y0), (x1, y1)];
        let a = self.area;
        match swatch {
            Swatch::Fill(c) => {
                a.draw(&Rectangle::new(rect, c.filled()))?;
                a.draw(&Rectangle::new(
                    rect,
                    RGBColor(150, 150, 150).stroke_width(1),
                ))?;
            }
            Swatch::Building(c) => {
                a.draw(&Rectangle::new(rect, c.filled()))?;
                a.draw(&Rectangle::new(rect, OUTLINE.stroke_width(1)))?;
            }
            Swatch::Edged(fill, edge) => {
                a.draw(&Rectangle::new(rect, fill.filled()))?;
                a.draw(&Rectangle::new(rect, edge.stroke_width(2)))?;
            }
            Swatch::Outline(c) => {
                a.draw(&Rectangle::new(rect, c.stroke_width(1)))?;
            }
            Swatch::Hatch => {
                a.draw(&Rectangle::new(rect, OPEN.filled()))?;
                let ink = blend_rgb(OPEN, UNSEEN_HATCH.0, UNSEEN_HATCH.1);
                let period = UNSEEN_HATCH.2 as i32;
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        if (x + y).rem_euclid(period) == 0 {
                            a.draw_pixel((x, y), &ink)?;
                        }
                    }
                }
                a.draw(&Rectangle::new(
                    rect,
                    RGBColor(150, 150, 150).stroke_width(1),
                ))?;
            }
            Swatch::Target => {
                target_marker(a, ((x0 + x1) / 2, self.y), OPEN)?;
            }
            Swatch::Track(c) => {
                thick_path(a, &[(x0, y1), (x0 + 8, y0 + 3), (x1 - 6, self.y)], *c)?;
                uav_marker(a, (x1 - 6, self.y), *c)?;
            }
        }
        let mut x = x1 + 10;
        if let Some(symbol) = symbol {
            x = self.symbol(symbol, x)?;
        }
        a.draw_text(text, &Self::text_style(14), (x, self.y))?;
        self.y += Self::ROW_PX;
        Ok(())
    }

    /// Draws `symbol` with its left edge at `x` on the current row; returns where text may
    /// follow.
    fn symbol(&self, symbol: Symbol<'_>, x: i32) -> anyhow::Result<i32> {
        let base_style = Self::text_style(15);
        let small_style = Self::text_style(11);
        let (base, small, rise) = match symbol {
            Symbol::Bar(base) => (base, None, 0),
            Symbol::Sup(base, sup) => (base, Some(sup), -5),
            Symbol::Sub(base, sub) => (base, Some(sub), 5),
        };
        let (w, _) = self.area.estimate_text_size(base, &base_style)?;
        let w = w as i32;
        self.area.draw_text(base, &base_style, (x, self.y))?;
        if let Symbol::Bar(_) = symbol {
            self.area.draw(&PathElement::new(
                vec![(x + 1, self.y - 10), (x + w - 1, self.y - 10)],
                BLACK.stroke_width(1),
            ))?;
        }
        let mut end = x + w;
        if let Some(small) = small {
            self.area
                .draw_text(small, &small_style, (end + 1, self.y + rise))?;
            let (sw, _) = self.area.estimate_text_size(small, &small_style)?;
            end += 1 + sw as i32;
        }
        Ok(end + 6)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::path::PathBuf;

    use protocol::raster::Coverage;
    use protocol::wire::TargetTruth;
    use uav_agent::occupancy::OemCell;

    use super::*;
    use crate::observe::metrics::FusedSets;
    use crate::pictures::register_fonts;

    /// Where a test writes its pictures: `$SETFLEET_KEEP_MAPS` (kept) or a fresh temp dir
    /// (removed when the guard drops).
    struct OutDir {
        path: PathBuf,
        keep: bool,
    }

    impl OutDir {
        fn new(name: &str) -> OutDir {
            let (path, keep) = match std::env::var_os("SETFLEET_KEEP_MAPS") {
                Some(dir) => (PathBuf::from(dir).join(name), true),
                None => (
                    std::env::temp_dir().join(format!(
                        "setfleet-maps-{}-{name}-{}",
                        std::process::id(),
                        std::time::SystemTime::now()
                            .duration_since(std::time::UNIX_EPOCH)
                            .unwrap()
                            .as_nanos()
                    )),
                    false,
                ),
            };
            std::fs::create_dir_all(&path).unwrap();
            OutDir { path, keep }
        }
    }

    impl Drop for OutDir {
        fn drop(&mut self) {
            if self.keep {
                eprintln!("pictures kept in {}", self.path.display());
            } else {
                let _ = std::fs::remove_dir_all(&self.path);
            }
        }
    }

    fn small_scenario() -> Scenario {
        Scenario::load(
            None,
            &[
                "region.half_extent_m=40".into(),
                "targets.count=3".into(),
                "uavs.count=2".into(),
            ],
        )
        .unwrap()
    }

    fn assert_png(path: &Path) {
        let bytes = std::fs::read(path).unwrap();
        assert!(
            bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
            "{} is not a PNG",
            path.display()
        );
        assert!(
            bytes.len() > 10_000,
            "{} is only {} bytes",
            path.display(),
            bytes.len()
        );
    }

    /// Paints with `paint` into memory; returns the picture's RGB bytes and the plot raster.
    fn paint_in_memory(
        paint: impl FnOnce(&Area<'_>) -> anyhow::Result<PlotRaster>,
    ) -> (Vec<u8>, PlotRaster) {
        let mut buf = vec![0u8; SIZE.0 as usize * SIZE.1 as usize * 3];
        let raster = {
            let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
            let raster = paint(&root).unwrap();
            root.present().unwrap();
            raster
        };
        (buf, raster)
    }

    /// The picture's colour at ground point `(x, y)`.
    fn colour_at(buf: &[u8], raster: &PlotRaster, x: f64, y: f64) -> [u8; 3] {
        let (px, py) = raster.pixel_of(x, y).unwrap();
        let (col, row) = (raster.left + px as i32, raster.top + py as i32);
        let i = (row as usize * SIZE.0 as usize + col as usize) * 3;
        [buf[i], buf[i + 1], buf[i + 2]]
    }

    /// The world of `scenario` after `steps` steps, with each UAV's track.
    fn flown(scenario: &Scenario, steps: u32) -> (World, Vec<Vec<[f64; 2]>>) {
        let mut world = World::new(scenario).unwrap();
        let mut tracks = vec![Vec::new(); world.uav_count()];
        for _ in 0..steps {
            for (track, uav) in tracks.iter_mut().zip(world.uavs()) {
                track.push([uav.state.position.x, uav.state.position.y]);
            }
            world.advance();
        }
        (world, tracks)
    }

    fn truth_of(world: &World) -> Vec<TargetTruth> {
        world
            .targets()
            .iter()
            .map(|car| TargetTruth {
                id: car.id,
                reserved: 0,
                ground: [car.position.x, car.position.y],
                heading: car.heading,
                speed: car.speed_mps,
            })
            .collect()
    }

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

    fn synthetic_state(scenario: &Scenario, world: &World) -> FinalState {
        let grid = scenario.grid();
        let targets = truth_of(world);
        let mut obstacle_free = CellSet::empty(&grid);
        for b in &world.scene().buildings {
            let r = scenario.targets.safety_distance_m;
            for iy in 0..grid.ny {
                for ix in 0..grid.nx {
                    let c = grid.cell_centre((ix, iy));
                    if c.x > b.min.x - r
                        && c.x < b.max.x + r
                        && c.y > b.min.y - r
                        && c.y < b.max.y + r
                    {
                        obstacle_free.set((ix, iy), true);
                    }
                }
            }
        }
        let mut explored = CellSet::empty(&grid);
        explored.fill_disc(&grid, Point2::new(-15.0, -15.0), 18.0, Coverage::Inner);
        explored.and_not_assign(&obstacle_free);
        let mut undetected = CellSet::full(&grid);
        undetected.and_not_assign(&explored);
        undetected.and_not_assign(&obstacle_free);
        let mut unseen = CellSet::empty(&grid);
        unseen.fill_disc(&grid, Point2::new(20.0, 20.0), 10.0, Coverage::Outer);
        let mut sets = BTreeMap::new();
        for t in targets.iter().take(2) {
            let mut s = CellSet::empty(&grid);
            s.fill_disc(
                &grid,
                Point2::new(t.ground[0], t.ground[1]),
                4.0,
                Coverage::Outer,
            );
            sets.insert(t.id, s);
        }
        FinalState {
            step: 40,
            time_s: 20.0,
            uav: 0,
            sets: FusedSets {
                undetected,
                targets: sets,
                obstacle_free,
                explored,
                unseen,
            },
            targets,
        }
    }

    #[test]
    fn the_sets_show_every_layer_over_the_city() {
        register_fonts().unwrap();
        let scenario = small_scenario();
        let (world, tracks) = flown(&scenario, 40);
        let state = synthetic_state(&scenario, &world);
        let buildings = &world.scene().buildings;

        let (buf, raster) =
            paint_in_memory(|root| paint_sets(root, &state, &tracks, &scenario, buildings));
        // A building, under S^o.
        if let Some(b) = buildings.first() {
            let (x, y) = (0.5 * (b.min.x + b.max.x), 0.5 * (b.min.y + b.max.y));
            let c = colour_at(&buf, &raster, x, y);
            assert_ne!(c, rgb(OPEN));
            assert_ne!(c, [255, 255, 255]);
        }
        // Inside target 0's set, south of its marker: tinted with its colour.
        let t = &state.targets[0];
        let inside = colour_at(&buf, &raster, t.ground[0], t.ground[1] - 2.5);
        let expected = target_colour(t.id);
        let tinted_alone = blend(rgb(OPEN), expected, TARGET_ALPHA);
        assert_ne!(inside, rgb(OPEN));
        let distance = |a: [u8; 3], b: [u8; 3]| {
            (0..3)
                .map(|k| (i32::from(a[k]) - i32::from(b[k])).abs())
                .sum::<i32>()
        };
        assert!(
            distance(inside, tinted_alone) < distance(rgb(OPEN), tinted_alone),
            "{inside:?} is not tinted towards {expected:?}"
        );

        let dir = OutDir::new("sets");
        let path = dir.path.join("sets.png");
        draw_sets(&state, &tracks, &scenario, &path).unwrap();
        assert_png(&path);
    }

    #[test]
    fn sets_on_another_grid_are_refused() {
        register_fonts().unwrap();
        let scenario = small_scenario();
        let (world, tracks) = flown(&scenario, 2);
        let state = synthetic_state(&scenario, &world);
        let bigger = Scenario::load(None, &["region.half_extent_m=60".into()]).unwrap();
        let dir = OutDir::new("refused");
        let err = draw_sets(&state, &tracks, &bigger, &dir.path.join("sets.png")).unwrap_err();
        assert!(err.to_string().contains("grid"), "{err}");
    }

    #[test]
    fn cell_spans_cover_a_pixel_and_clamp_to_the_grid() {
        // Cells of 0.5 m from -10: a pixel over [0.1, 0.9] touches cells 20 and 21.
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 0.1, 0.9), Some((20, 21)));
        // A pixel inside one cell touches only it.
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 0.1, 0.2), Some((20, 20)));
        // Exactly on a cell's edges: only that cell.
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 0.0, 0.5), Some((20, 20)));
        assert_eq!(cells_spanned(-10.0, 0.5, 40, -11.0, -9.8), Some((0, 0)));
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 9.9, 12.0), Some((39, 39)));
        assert_eq!(cells_spanned(-10.0, 0.5, 40, 10.0, 12.0), None);
        assert_eq!(cells_spanned(-10.0, 0.5, 40, -12.0, -10.0), None);
    }

    /// A real case, the estimators of a small fleet run in-process: writes `map.png` and
    /// `sets.png` to `$SETFLEET_KEEP_MAPS/real` for a look.
    #[test]
    #[ignore = "slow (renders frames); run with SETFLEET_KEEP_MAPS=DIR to look at the pictures"]
    fn real_case_pictures() {
        use crate::bench::estimator::FleetSim;
        use crate::observe::metrics::ObservedEstimate;
        use uav_agent::estimator::EstimatorConfig;

        register_fonts().unwrap();
        let scenario = Scenario::load(
            None,
            &[
                "region.half_extent_m=100".into(),
                "targets.count=5".into(),
                "uavs.count=3".into(),
            ],
        )
        .unwrap();
        let steps = 120;
        let mut sim = FleetSim::new(&scenario).unwrap();
        let mut tracks = vec![Vec::new(); sim.uav_count()];
        for _ in 0..steps {
            sim.step().unwrap();
            for (track, est) in tracks.iter_mut().zip(sim.estimators()) {
                if let Some(pose) = est.state().pose {
                    track.push([pose.position.x, pose.position.y]);
                }
            }
        }
        let config = EstimatorConfig::from_scenario(&scenario);
        let mut oem = OccupancyMap::new(config.oem_grid);
        let mut observed = Vec::new();
        for bytes in sim.last_messages() {
            let (estimate, _) = ObservedEstimate::decode(bytes, &config).unwrap();
            observed.push(estimate);
        }
        for est in sim.estimators() {
            oem.merge(&est.state().oem);
        }
        let sets = FusedSets::of_agent(&observed[0], &observed, &config, f64::INFINITY);
        // Traffic does not depend on the UAVs: a second world gives the cars of the last frame.
        let mut shadow = World::new(&scenario).unwrap();
        for _ in 0..steps - 1 {
            shadow.advance();
        }
        let state = FinalState {
            step: shadow.step(),
            time_s: shadow.time_s(),
            uav: 0,
            sets,
            targets: truth_of(&shadow),
        };
        let dir = OutDir::new("real");
        let start = std::time::Instant::now();
        draw_map(&oem, &scenario, &dir.path.join("map.png")).unwrap();
        draw_sets(&state, &tracks, &scenario, &dir.path.join("sets.png")).unwrap();
        eprintln!("both pictures drawn in {:?}", start.elapsed());
        assert_png(&dir.path.join("map.png"));
        assert_png(&dir.path.join("sets.png"));
    }
}
