//! Second viewpoints for shadows (`guidance.second_viewpoints`, the `setfleet` planner).
//!
//! Ground hidden from where the UAVs flew (`H̄`) and still in `X̄` is a *pocket*: a pass in the
//! direction that hid it does not clear it, and it regrows into the ground around it at the
//! targets' speed. The map knows the buildings that hid it (the OEM heights), so it can predict
//! a viewpoint from which the pocket is visible: the camera looking at the pocket from another
//! side.
//!
//! At each decision ([`SecondViewpoint::choose`]):
//! 1. **The pocket.** The pockets are the planning cells of `X̄ ∩ H̄` in the deciding UAV's
//!    *own ground* (its lane, behind its front with lanes). The ground is cut into square
//!    blocks half the camera's footprint deep, about what one view takes in; the block holding
//!    most pocket cells is chosen (ties: the first in row order), if it holds at least
//!    [`MIN_POCKET_CELLS`].
//! 2. **The viewpoint.** For [`HEADINGS`] headings `θ` evenly spread, the camera at the UAV's
//!    altitude is placed so that its optical axis meets the ground at the pocket's barycentre,
//!    looking along `θ`; the predicted view (with the map's buildings) tells how many of the
//!    pocket's cells it sees. The heading seeing most is the viewpoint (ties: the first
//!    heading), if it sees at least [`MIN_VISIBLE_FRACTION`] of the pocket.
//! 3. **Worth the detour.** The planner charges `λ` m² per metre its view centre is from where
//!    it pulls (the distance term). The viewpoint is flown to when what it clears, the visible
//!    cells' area plus the pocket's growth over the planner's growth horizon
//!    ([`super::growth`]), exceeds `λ` times the detour: the distance from the UAV's view centre to
//!    the pocket's barycentre.
//! 4. **The pull.** While a viewpoint is flown to, the planner's distance term measures how far
//!    a sequence ends from it ([`SecondViewpoint::distance_m`]): the distance from the view
//!    centre to the barycentre, plus the camera's ground offset `D` times `1 - cos` of the
//!    heading error, so the UAV arrives looking from the predicted side. Its views are valued
//!    as always (with the map's shadows), so a sequence that sees into the pocket is worth it.
//!
//! Deterministic: fixed headings, row-major scans and ties broken by order.

use protocol::camera::CameraPose;
use sets::grid::GroundGrid;
use sets::math::{Point2, Point3};
use sets::raster::{CellBox, CellSet};

use super::GuidanceParams;
use super::growth::{self, Growth};
use super::view::{self, GroundPredictor, ObstacleCell};

/// Smallest pocket a viewpoint is planned for, planning cells.
pub const MIN_POCKET_CELLS: u64 = 8;
/// Headings tried for a viewpoint.
pub const HEADINGS: usize = 8;
/// Smallest share of the pocket a viewpoint must be predicted to see.
pub const MIN_VISIBLE_FRACTION: f64 = 0.25;

/// A viewpoint planned for a pocket.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SecondViewpoint {
    /// The pocket's barycentre, where the view centre is pulled.
    pub target: Point2,
    /// The heading to look at it along, radians.
    pub heading: f64,
    /// The camera's ground offset: from its position to its view centre, metres.
    pub offset_m: f64,
    /// The pocket's cells the viewpoint is predicted to see.
    pub visible_cells: u64,
}

impl SecondViewpoint {
    /// The viewpoint for the densest block of `pockets` (planning cells of `X̄ ∩ H̄` in the
    /// deciding UAV's own ground, on `grid`), for the camera at `position` and `yaw` whose
    /// footprint is `footprint_depth_m` deep, if one is predicted to see enough of it and is
    /// worth the detour (module docs).
    pub fn choose(
        params: &GuidanceParams,
        grid: &GroundGrid,
        pockets: &CellSet,
        (position, yaw): (Point3, f64),
        footprint_depth_m: f64,
        obstacles: &[ObstacleCell],
        predictor: &mut GroundPredictor,
    ) -> Option<SecondViewpoint> {
        let side = (footprint_depth_m / 2.0 / grid.cell_m).ceil() as u32;
        let pocket = densest_block(grid, pockets, side)?;
        let cells = pocket.count();
        if cells < MIN_POCKET_CELLS {
            return None;
        }
        let target = pocket.barycentre(grid)?;
        let mut best: Option<SecondViewpoint> = None;
        for k in 0..HEADINGS {
            let heading =
                -std::f64::consts::PI + 2.0 * std::f64::consts::PI * k as f64 / HEADINGS as f64;
            let Some(pose) = looking_at(params, target, position.z, heading) else {
                continue;
            };
            let mut seen = CellSet::empty(grid);
            predictor.add_visible_ground_within(
                &mut seen,
                grid,
                &params.camera,
                &pose,
                obstacles,
                &pocket,
            );
            let visible_cells = seen.count();
            if best.is_none_or(|b| visible_cells > b.visible_cells) {
                let here = Point2::new(pose.position.x, pose.position.y);
                best = Some(SecondViewpoint {
                    target,
                    heading,
                    offset_m: (target - here).norm(),
                    visible_cells,
                });
            }
        }
        let best = best?;
        if (best.visible_cells as f64) < MIN_VISIBLE_FRACTION * cells as f64 {
            return None;
        }
        let rings = growth::horizon_rings(params, grid);
        let growth_m2 =
            (Growth::of(&pocket, rings).grown_cells() - pocket.count()) as f64 * grid.cell_area();
        let gain_m2 = best.visible_cells as f64 * grid.cell_area() + growth_m2;
        let here = view::view_centre(&params.camera, &CameraPose { position, yaw });
        let detour_m = (target - here).norm();
        (gain_m2 > params.lambda * detour_m).then_some(best)
    }

    /// How far a sequence ending with its view centre at `centre` and heading `yaw` is from
    /// the viewpoint, metres: the view centre's distance to the pocket plus the ground offset
    /// times `1 - cos` of the heading error.
    pub fn distance_m(&self, centre: &Point2, yaw: f64) -> f64 {
        (centre - self.target).norm() + self.offset_m * (1.0 - (yaw - self.heading).cos())
    }
}

/// The camera pose at altitude `z` looking along `heading` whose optical axis meets the
/// ground at `target` (`None` if the camera's axis does not reach the ground).
fn looking_at(params: &GuidanceParams, target: Point2, z: f64, heading: f64) -> Option<CameraPose> {
    let at_origin = CameraPose {
        position: Point3::new(0.0, 0.0, z),
        yaw: heading,
    };
    let centre = view::view_centre(&params.camera, &at_origin);
    let offset = centre - Point2::origin();
    if offset.norm() <= f64::EPSILON {
        return None;
    }
    let position = target - offset;
    Some(CameraPose {
        position: Point3::new(position.x, position.y, z),
        yaw: heading,
    })
}

/// The cells of `set` in the square block of `side` cells (blocks laid from the grid's first
/// cell) that holds most of them (ties: the first block in row-major order), or `None` when
/// `set` is empty.
fn densest_block(grid: &GroundGrid, set: &CellSet, side: u32) -> Option<CellSet> {
    let side = side.max(1);
    let mut best: Option<(u64, CellBox)> = None;
    for by in (0..grid.ny).step_by(side as usize) {
        for bx in (0..grid.nx).step_by(side as usize) {
            let block = CellBox {
                x0: bx,
                y0: by,
                x1: (bx + side - 1).min(grid.nx - 1),
                y1: (by + side - 1).min(grid.ny - 1),
            };
            let count = set.count_in_box(&block);
            if count > 0 && best.is_none_or(|(c, _)| count > c) {
                best = Some((count, block));
            }
        }
    }
    let (_, block) = best?;
    let mut pocket = set.clone();
    pocket.crop(&block);
    Some(pocket)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::guidance::setfleet::tests::params;
    use sets::grid::Rect;

    fn block(grid: &GroundGrid, (x0, y0): (u32, u32), (x1, y1): (u32, u32)) -> CellSet {
        let mut s = CellSet::empty(grid);
        for iy in y0..=y1 {
            s.fill_row_span(iy, x0, x1);
        }
        s
    }

    #[test]
    fn the_densest_block_is_chosen_first_in_row_order_on_ties() {
        let grid = GroundGrid::new(50.0, 2.5); // 40 x 40, blocks of 10: 4 x 4
        let sparse = block(&grid, (1, 1), (2, 2));
        let dense = block(&grid, (20, 20), (24, 23));
        let twin = block(&grid, (30, 1), (34, 4));
        let mut all = sparse.clone();
        all.or_assign(&dense);
        assert_eq!(densest_block(&grid, &all, 10), Some(dense.clone()));
        // Equal blocks: the first in row-major order.
        all.or_assign(&twin);
        assert_eq!(densest_block(&grid, &all, 10), Some(twin));
        // A group across blocks is cut at the block's edges.
        let across = block(&grid, (8, 0), (13, 0));
        assert_eq!(densest_block(&grid, &across, 10).unwrap().count(), 4);
        assert_eq!(densest_block(&grid, &CellSet::empty(&grid), 10), None);
    }

    /// A pocket north of a tall building is hidden from a camera looking north from the south
    /// of it: the viewpoint looks at it from another side, and its pull is least there.
    #[test]
    fn a_pocket_behind_a_building_gets_a_viewpoint_from_another_side() {
        let p = params();
        let grid = p.grids.coarse;
        let tower = ObstacleCell {
            rect: Rect {
                min: Point2::new(-10.0, 0.0),
                max: Point2::new(10.0, 10.0),
            },
            height_m: 60.0,
        };
        // The ground just north of the tower, which a camera looking north cannot see.
        let pocket = {
            let (x0, y0) = grid.cell_of(&Point2::new(-8.0, 11.0)).unwrap();
            let (x1, y1) = grid.cell_of(&Point2::new(8.0, 30.0)).unwrap();
            block(&grid, (x0, y0), (x1, y1))
        };
        let mut predictor = GroundPredictor::new(&grid);
        let north = std::f64::consts::FRAC_PI_2;
        let from_south = looking_at(&p, Point2::new(0.0, 20.0), 80.0, north).unwrap();
        let mut seen = CellSet::empty(&grid);
        predictor.add_visible_ground_within(
            &mut seen,
            &grid,
            &p.camera,
            &from_south,
            &[tower],
            &pocket,
        );
        assert!(
            seen.count() < pocket.count() / 2,
            "{} of {}",
            seen.count(),
            pocket.count()
        );
        let choose = |params: &GuidanceParams, predictor: &mut GroundPredictor| {
            let at = (Point3::new(0.0, -100.0, 80.0), north);
            SecondViewpoint::choose(params, &grid, &pocket, at, 120.0, &[tower], predictor)
        };
        let v = choose(&p, &mut predictor).expect("a viewpoint");
        assert!(v.visible_cells as f64 >= MIN_VISIBLE_FRACTION * pocket.count() as f64);
        assert!((v.heading - north).abs() > 1.0, "{v:?}");
        assert!(v.distance_m(&v.target, v.heading) < 1e-9);
        assert!(v.distance_m(&v.target, v.heading + 1.0) > 0.0);
        // Too far to be worth it with a prohibitive distance weight.
        let mut costly = p.clone();
        costly.lambda = 1e9;
        let far = choose(&costly, &mut predictor);
        assert_eq!(far, None);
    }
}
