//! The occupancy elevation map built from real frames, compared with the world's buildings.

use estimator::occupancy::OemStatus;
use protocol::scenario::Scenario;
use sets::grid::Rect;
use sim::{Fleet, FleetOptions};

/// Height tolerance of obstacle cells: the depth noise moves a roof point by at most
/// `|w| * range` along its ray, under 2 m at the ranges of the default camera; 3 m leaves room.
const HEIGHT_TOLERANCE_M: f64 = 3.0;
/// Horizontal slack: a facade point can be displaced along its ray by the same amount.
const HORIZONTAL_SLACK_M: f64 = 3.0;

fn overlaps(a: &Rect, min: (f64, f64), max: (f64, f64), slack: f64) -> bool {
    a.min.x <= max.0 + slack
        && a.max.x >= min.0 - slack
        && a.min.y <= max.1 + slack
        && a.max.y >= min.1 - slack
}

#[test]
fn map_marks_buildings_with_their_heights_and_open_ground() {
    // Each UAV maps alone, flying straight on: no estimate is exchanged.
    let options = FleetOptions {
        exchange: false,
        ..FleetOptions::default()
    };
    let mut fleet = Fleet::new(&Scenario::default(), options).expect("world");
    for _ in 0..30 {
        fleet.step().expect("frame accepted");
    }
    let buildings = &fleet.world().scene().buildings;
    let estimators = fleet.estimators();
    let mut map = estimators[0].state().oem.clone();
    for e in &estimators[1..] {
        map.merge(&e.state().oem);
    }
    let (mut obstacles, mut grounds, mut roofs_checked) = (0, 0, 0);
    for (index, cell) in map.known_cells() {
        let rect = map.grid().cell_rect(index);
        match cell.status {
            OemStatus::Obstacle => {
                obstacles += 1;
                let touching: Vec<f64> = buildings
                    .iter()
                    .filter(|b| {
                        overlaps(
                            &rect,
                            (b.min.x, b.min.y),
                            (b.max.x, b.max.y),
                            HORIZONTAL_SLACK_M,
                        )
                    })
                    .map(|b| b.height)
                    .collect();
                let tallest = touching.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                assert!(
                    !touching.is_empty(),
                    "obstacle cell {index:?} touches no building"
                );
                assert!(
                    (cell.height_m as f64) <= tallest + HEIGHT_TOLERANCE_M,
                    "cell {index:?}: {} m over a {tallest} m building",
                    cell.height_m
                );
                // A cell well inside one building's footprint (and no other's) only sees roof.
                let inside: Vec<_> = buildings
                    .iter()
                    .filter(|b| {
                        rect.min.x >= b.min.x + HORIZONTAL_SLACK_M
                            && rect.max.x <= b.max.x - HORIZONTAL_SLACK_M
                            && rect.min.y >= b.min.y + HORIZONTAL_SLACK_M
                            && rect.max.y <= b.max.y - HORIZONTAL_SLACK_M
                    })
                    .collect();
                if let [b] = inside.as_slice() {
                    roofs_checked += 1;
                    assert!(
                        (cell.height_m as f64 - b.height).abs() <= HEIGHT_TOLERANCE_M,
                        "roof cell {index:?}: {} m for a {} m building",
                        cell.height_m,
                        b.height
                    );
                }
            }
            OemStatus::Ground => {
                grounds += 1;
                let c = map.grid().cell_centre(index);
                assert!(
                    !buildings
                        .iter()
                        .any(|b| c.x > b.min.x && c.x < b.max.x && c.y > b.min.y && c.y < b.max.y),
                    "ground cell {index:?} has its centre under a building"
                );
            }
            OemStatus::Unknown => {}
        }
    }
    eprintln!("{obstacles} obstacle cells ({roofs_checked} roofs), {grounds} ground cells");
    assert!(obstacles > 0 && grounds > 0 && roofs_checked > 0);
}
