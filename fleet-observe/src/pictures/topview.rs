//! `topview.png`: the city from above with the cars, the fleet and one UAV's field of view.

use std::path::Path;

use plotters::prelude::*;
use sets::math::{Point2, Vector2};
use world_server::World;

use super::{FONT, palette};

/// Side of the picture, pixels.
const SIDE_PX: u32 = 900;

/// Grey of a building: the taller, the darker.
pub(crate) fn building_shade(height: f64, lo: f64, hi: f64) -> RGBColor {
    let t = if hi > lo {
        ((height - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.5
    };
    let g = (200.0 - 140.0 * t).round() as u8;
    RGBColor(g, g, g)
}

/// Corners of a car's box on the ground.
fn car_outline(centre: Point2, heading: f64, length: f64, width: f64) -> Vec<(f64, f64)> {
    let (s, c) = heading.sin_cos();
    let (hl, hw) = (length / 2.0, width / 2.0);
    [(hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw)]
        .into_iter()
        .map(|(a, b)| (centre.x + a * c - b * s, centre.y + a * s + b * c))
        .collect()
}

/// The paved strip of half width `hw` along the centreline `a b`, squared off a half width
/// beyond each end so that roads meeting at an angle join without a gap.
fn road_quad(a: Point2, b: Point2, hw: f64) -> Vec<(f64, f64)> {
    let d = b - a;
    let len = d.norm();
    let (u, n) = if len > 0.0 {
        (d / len * hw, Vector2::new(-d.y, d.x) / len * hw)
    } else {
        (Vector2::new(hw, 0.0), Vector2::new(0.0, hw))
    };
    [a - u + n, a - u - n, b + u - n, b + u + n]
        .iter()
        .map(|p| (p.x, p.y))
        .collect()
}

/// Draws the world at its current step, highlighting UAV `focus`'s field of view on flat
/// ground.
pub fn draw_topview(world: &World, focus: usize, path: &Path) -> anyhow::Result<()> {
    let city = world.scene();
    let h = city.half_extent;
    let root = BitMapBackend::new(path, (SIDE_PX, SIDE_PX)).into_drawing_area();
    root.fill(&WHITE)?;
    let caption = format!(
        "t = {:.1} s, step {}, UAV {focus} field of view",
        world.time_s(),
        world.step()
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, (FONT, 20))
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

    // Ground, then roads, then buildings.
    chart.draw_series(std::iter::once(Rectangle::new(
        [(-h, -h), (h, h)],
        RGBColor(232, 240, 222).filled(),
    )))?;
    let hw = city.profile.half_width;
    let road = RGBColor(160, 160, 160).filled();
    chart.draw_series(
        (city.roads.centrelines(h).into_iter())
            .map(|(a, b)| Polygon::new(road_quad(a, b, hw), road)),
    )?;
    let [lo, hi] = world.scenario().region.building_height_m;
    for b in &city.buildings {
        let shade = building_shade(b.height, lo, hi).filled();
        chart.draw_series(b.footprint().into_iter().map(|part| {
            Polygon::new(part.iter().map(|p| (p.x, p.y)).collect::<Vec<_>>(), shade)
        }))?;
    }

    // The focused UAV's footprint, under the cars so they stay visible.
    if let Some(footprint) = world.camera(focus).and_then(|c| c.image_ground_footprint()) {
        let pts: Vec<(f64, f64)> = footprint.iter().map(|p| (p.x, p.y)).collect();
        let colour = palette(focus);
        chart.draw_series(std::iter::once(Polygon::new(
            pts.clone(),
            colour.mix(0.25).filled(),
        )))?;
        let mut closed = pts;
        closed.push(closed[0]);
        chart.draw_series(std::iter::once(PathElement::new(
            closed,
            colour.stroke_width(2),
        )))?;
    }

    let [length, width, _] = world.scenario().targets.size_m;
    let car_font = (FONT, 12).into_font().color(&RGBColor(150, 0, 0));
    for car in world.targets() {
        let outline = car_outline(car.position, car.heading, length, width);
        chart.draw_series(std::iter::once(Polygon::new(outline, RED.filled())))?;
        chart.draw_series(std::iter::once(Text::new(
            format!("T{}", car.id),
            (car.position.x + 3.0, car.position.y + 3.0),
            car_font.clone(),
        )))?;
    }

    for (i, uav) in world.uavs().iter().enumerate() {
        let p = uav.state.position;
        let colour = palette(i);
        let (s, c) = uav.state.yaw.sin_cos();
        let nose = (p.x + 12.0 * c, p.y + 12.0 * s);
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(p.x, p.y), nose],
            colour.stroke_width(3),
        )))?;
        chart.draw_series(std::iter::once(Circle::new((p.x, p.y), 6, colour.filled())))?;
        chart.draw_series(std::iter::once(Text::new(
            format!("UAV {i} ({:.0} m)", p.z),
            (p.x + 5.0, p.y - 5.0),
            (FONT, 13).into_font().color(&colour),
        )))?;
    }
    root.present()?;
    Ok(())
}
