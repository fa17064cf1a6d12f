//! `city.png`: an imported city from above: buildings shaded by height, the roads cars may
//! use, and the road pieces the importer cut, coloured by why.

use std::path::Path;

use city::scene::{CityScene, CutReason};
use plotters::prelude::*;

use super::FONT;
use super::topview::building_shade;

/// Side of the picture, pixels.
const SIDE_PX: u32 = 900;

/// The colour of a cut piece, by why it was cut.
fn cut_colour(reason: &CutReason) -> RGBColor {
    match reason {
        CutReason::Clearance { .. } => RGBColor(214, 39, 40),
        CutReason::Tunnel | CutReason::Bridge | CutReason::Layer | CutReason::Covered => {
            RGBColor(148, 103, 189)
        }
        CutReason::Unreachable => RGBColor(255, 127, 14),
    }
}

/// Draws the scene; buildings take their heights from the storey height and the default.
pub fn draw_city(
    scene: &CityScene,
    storey_height_m: f64,
    default_height_m: f64,
    path: &Path,
) -> anyhow::Result<()> {
    let h = scene.half_extent_m;
    let heights: Vec<f64> = scene
        .buildings
        .iter()
        .map(|b| b.height(storey_height_m, default_height_m).0)
        .collect();
    let lo = heights.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = heights.iter().copied().fold(0.0, f64::max);
    let root = BitMapBackend::new(path, (SIDE_PX, SIDE_PX)).into_drawing_area();
    root.fill(&WHITE)?;
    let caption = format!(
        "{} around {:.4}, {:.4} (buildings {:.0}-{:.0} m)",
        scene.source.osm_file,
        scene.source.centre[0],
        scene.source.centre[1],
        lo.min(hi),
        hi
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, (FONT, 18))
        .margin(12)
        .x_label_area_size(34)
        .y_label_area_size(46)
        .build_cartesian_2d(-h..h, -h..h)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x east (m)")
        .y_desc("y north (m)")
        .label_style((FONT, 13))
        .draw()?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(-h, -h), (h, h)],
        RGBColor(232, 240, 222).filled(),
    )))?;
    for (b, &height) in scene.buildings.iter().zip(&heights) {
        let shade = building_shade(height, lo, hi);
        chart.draw_series(b.parts.iter().map(|part| {
            Polygon::new(
                part.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
                shade.filled(),
            )
        }))?;
    }
    let roads = &scene.roads;
    chart
        .draw_series(roads.edges.iter().map(|e| {
            let (a, b) = (roads.points[e.a as usize], roads.points[e.b as usize]);
            PathElement::new(
                vec![(a[0], a[1]), (b[0], b[1])],
                RGBColor(40, 40, 40).stroke_width(3),
            )
        }))?
        .label("drivable")
        .legend(|(x, y)| {
            PathElement::new(
                vec![(x, y), (x + 18, y)],
                RGBColor(40, 40, 40).stroke_width(3),
            )
        });
    for (name, sample) in [
        (
            "cut: too close to a building",
            CutReason::Clearance {
                building: String::new(),
                closest_m: 0.0,
            },
        ),
        ("cut: tunnel, bridge, layer or covered", CutReason::Tunnel),
        ("cut: unreachable", CutReason::Unreachable),
    ] {
        let colour = cut_colour(&sample);
        chart
            .draw_series(
                scene
                    .cuts
                    .iter()
                    .filter(|c| cut_colour(&c.reason) == colour)
                    .map(|c| {
                        PathElement::new(
                            c.line.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
                            colour.stroke_width(2),
                        )
                    }),
            )?
            .label(name)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()?;
    root.draw(&Text::new(
        scene.source.attribution.clone(),
        (SIDE_PX as i32 - 330, SIDE_PX as i32 - 18),
        (FONT, 13).into_font().color(&BLACK),
    ))?;
    root.present()?;
    Ok(())
}
