//! `sets.png`: one agent's final fused sets over the city (the lowest id measured at the last
//! step; with perfect links every agent holds the same sets but `H̄`): explored ground,
//! `S^o`, `H̄`, `X̄`, each `X_j`, the true targets and the UAV tracks. A set is drawn at a
//! pixel when any cell the pixel touches belongs to it, so sets smaller than a pixel still
//! show.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use protocol::scenario::Scenario;
use sets::grid::GroundGrid;
use sets::math::Point2;
use sets::raster::CellSet;
use world_server::scene::Building;

use super::chart::{
    Area, Chart, OPEN, OUTSIDE, PANEL, TITLE_PX, build_chart, draw_axes, draw_frame, draw_outlines,
    draw_title, percent, write_picture,
};
use super::legend::{Hatch, Legend, Swatch, Symbol, target_marker, thick_path, uav_marker};
use super::raster::{Pixels, PlotRaster, blend, blend_rgb, is_edge, mask, rgb};
use crate::observe::FinalState;
use crate::observe::metrics::FusedSets;
use crate::pictures::topview::building_shade;
use crate::pictures::{FONT, palette};

/// Explored ground: colour and opacity.
pub(super) const EXPLORED: (RGBColor, f64) = (RGBColor(150, 205, 150), 0.3);
/// `S^o`: colour and opacity.
pub(super) const OBSTACLE_NEIGHBOURHOOD: (RGBColor, f64) = (RGBColor(55, 65, 120), 0.4);
/// `X̄`: colour and opacity.
pub(super) const UNDETECTED: (RGBColor, f64) = (RGBColor(255, 185, 0), 0.45);
/// Opacity of a target set `X_j` (its colour is the target's palette colour).
pub(super) const TARGET_ALPHA: f64 = 0.45;
/// Hatch lines of `H̄`.
const UNSEEN_HATCH: Hatch = Hatch {
    ink: RGBColor(40, 40, 40),
    alpha: 0.75,
    period: 7,
};
/// Legend rows listed per kind (target sets, UAVs) before the rest are summarised.
const LEGEND_MAX_ROWS: usize = 10;

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
    write_picture(path, "sets.png", scenario, |root, buildings| {
        paint_sets(root, state, tracks, scenario, buildings).map(drop)
    })
}

/// The sets picture on `root`; returns where the plotting area lies.
pub(super) fn paint_sets(
    root: &Area<'_>,
    state: &FinalState,
    tracks: &[Vec<[f64; 2]>],
    scenario: &Scenario,
    buildings: &[Building],
) -> anyhow::Result<PlotRaster> {
    let grid = scenario.grid();
    root.fill(&WHITE)?;
    let (title_area, body) = root.split_vertically(TITLE_PX);
    draw_title(&title_area, &sets_title(state))?;
    let (panel, legend) = body.split_horizontally(PANEL.0);

    let half = view_half_extent(state, tracks, scenario);
    let mut chart = build_chart(&panel, half)?;
    let raster = PlotRaster::of(&chart, half)?;

    let mut pixels = paint_ground(&raster, scenario, buildings);
    paint_layers(&mut pixels, &raster, &state.sets, &grid);
    raster.blit(root, pixels)?;
    draw_axes(&mut chart)?;
    draw_outlines(&mut chart, buildings)?;
    draw_markers(root, &chart, state, tracks)?;
    draw_frame(&mut chart, half)?;

    draw_legend(&legend, &state.sets, tracks.len(), scenario)?;
    Ok(raster)
}

/// The picture's title: whose sets, when, and how many targets they identify.
fn sets_title(state: &FinalState) -> String {
    let sets = &state.sets;
    let truth_ids: Vec<u32> = state.targets.iter().map(|t| t.id).collect();
    let found = truth_ids
        .iter()
        .filter(|id| sets.targets.contains_key(id))
        .count();
    format!(
        "UAV {}'s final sets at t = {:.1} s (step {}): {found} of {} targets identified, \
         areas in % of the region",
        state.uav,
        state.time_s,
        state.step,
        truth_ids.len()
    )
}

/// Half the side of the view: it holds the region and anything drawn outside it.
fn view_half_extent(state: &FinalState, tracks: &[Vec<[f64; 2]>], scenario: &Scenario) -> f64 {
    let reach = tracks
        .iter()
        .flatten()
        .copied()
        .chain(state.targets.iter().map(|t| t.ground))
        .flat_map(|[x, y]| [x.abs(), y.abs()])
        .filter(|v| v.is_finite())
        .fold(0.0_f64, f64::max);
    let h = scenario.region.half_extent_m;
    if reach > h { reach * 1.03 } else { h }
}

/// The ground under the sets: open inside the grid, the view past it, and the buildings
/// shaded by height.
fn paint_ground(raster: &PlotRaster, scenario: &Scenario, buildings: &[Building]) -> Pixels {
    let [lo, hi] = scenario.region.building_height_m;
    let mut pixels = Pixels::new(raster);
    let bounds = scenario.grid().bounds();
    for py in 0..raster.height {
        let y = raster.y_centre(py);
        for px in 0..raster.width {
            let p = Point2::new(raster.x_centre(px), y);
            let colour = if bounds.contains(&p) { OPEN } else { OUTSIDE };
            pixels.put(px, py, rgb(colour));
        }
    }
    for b in buildings {
        pixels.fill_footprint(raster, b, rgb(building_shade(b.height, lo, hi)));
    }
    pixels
}

/// Blends the set layers over the ground: explored ground, `S^o`, `X̄`, each `X_j` (edged in
/// its colour), then the hatch of `H̄`.
fn paint_layers(pixels: &mut Pixels, raster: &PlotRaster, sets: &FusedSets, grid: &GroundGrid) {
    let cols = raster.cell_columns(grid);
    let rows = raster.cell_rows(grid);
    let explored = mask(&sets.explored, &cols, &rows);
    let neighbourhood = mask(&sets.obstacle_neighbourhood, &cols, &rows);
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
            if unseen[i] && (px + py) % UNSEEN_HATCH.period as usize == 0 {
                c = blend(c, UNSEEN_HATCH.ink, UNSEEN_HATCH.alpha);
            }
            pixels.put(px as u32, py as u32, c);
        }
    }
}

/// Each UAV's track with its last position, then the true targets, each labelled.
fn draw_markers(
    root: &Area<'_>,
    chart: &Chart<'_, '_>,
    state: &FinalState,
    tracks: &[Vec<[f64; 2]>],
) -> anyhow::Result<()> {
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
    Ok(())
}

/// The legend: the layers with their areas, the target sets and the `uavs` UAVs.
fn draw_legend(
    area: &Area<'_>,
    sets: &FusedSets,
    uavs: usize,
    scenario: &Scenario,
) -> anyhow::Result<()> {
    let grid = scenario.grid();
    let cells = grid.cell_count() as u64;
    let [lo, hi] = scenario.region.building_height_m;
    let share = |set: &CellSet| format!("{:.1} %", percent(set.count(), cells));
    let mut keys = Legend::new(area);
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
        &format!(
            "obstacle neighbourhoods, {}",
            share(&sets.obstacle_neighbourhood)
        ),
    )?;
    keys.entry(
        &Swatch::Hatch(UNSEEN_HATCH),
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
    for i in 0..uavs.min(LEGEND_MAX_ROWS) {
        keys.entry(
            &Swatch::Track(palette(i)),
            None,
            &format!("UAV {i}: track, last position"),
        )?;
    }
    if uavs > LEGEND_MAX_ROWS {
        keys.text(&format!("and {} more", uavs - LEGEND_MAX_ROWS))?;
    }
    Ok(())
}

/// Fails unless every set of `state` lives on the scenario's grid.
fn check_grid(state: &FinalState, scenario: &Scenario) -> anyhow::Result<()> {
    let grid = scenario.grid();
    let sets = &state.sets;
    let named: [(&str, &CellSet); 4] = [
        ("X\u{304}", &sets.undetected),
        ("S^o", &sets.obstacle_neighbourhood),
        ("explored", &sets.explored),
        ("H\u{304}", &sets.unseen),
    ];
    let targets = sets.targets.values().map(|s| ("X_j", &**s));
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

/// The colour of target `id` (its set and its marker).
pub(super) fn target_colour(id: u32) -> RGBColor {
    palette(id as usize)
}

#[cfg(test)]
mod tests {
    use estimator::occupancy::OccupancyMap;
    use protocol::radio::Radio;
    use world_server::World;

    use super::super::fixtures::{
        OutDir, assert_png, colour_at, flown, paint_in_memory, small_scenario, synthetic_state,
        truth_of,
    };
    use super::super::map::draw_map;
    use super::*;
    use crate::observe::metrics::FusedSets;
    use crate::pictures::register_fonts;

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

    /// A real case, the estimators of a small fleet run in-process: writes `map.png` and
    /// `sets.png` to `$SETFLEET_KEEP_MAPS/real` for a look.
    #[test]
    #[ignore = "slow (renders frames); run with SETFLEET_KEEP_MAPS=DIR to look at the pictures"]
    fn real_case_pictures() {
        use crate::observe::metrics::ObservedEstimate;
        use crate::observe::metrics::tests::guided_fleet as fleet;
        use estimator::EstimatorConfig;

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
        let mut sim = fleet(&scenario).unwrap();
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
        for bytes in sim.messages() {
            let (estimate, _) = ObservedEstimate::decode(bytes, &config).unwrap();
            observed.push(estimate);
        }
        for est in sim.estimators() {
            oem.merge(&est.state().oem);
        }
        let sets = FusedSets::of_agent(&observed[0], &observed, &config, &Radio::perfect());
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
