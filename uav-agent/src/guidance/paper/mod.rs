//! The paper's MPC (docs/design.md §4; the paper's Sections VI-VII): the `paper` planner.
//!
//! For every sequence of yaw increments in `U^h`, the UAV's own states are predicted with the
//! world's dynamics ([`protocol::flight::advance`]) at every CVS step of the horizon; the
//! predicted sets (the union of `X̄` and every `X_j`, on the grid `guidance.set_resolution`
//! names: the estimator's by default) are dilated by the targets' motion once per guidance
//! period and lose the ground the UAV will see in that period (its predicted field of view
//! less the shadows of known buildings, [`view`]) and the ground seen by the UAVs that already
//! decided this round (the token). The sequence minimising `J = Φ_X + λ Φ_d + κ Φ_h` (eq. 31)
//! wins:
//! - `Φ_X`: area of the predicted sets at the end of the horizon (eq. 32), m²;
//! - `Φ_d`: distance from the UAV's predicted ground position `p_g(x^u_{k+h})` to the nearest
//!   predicted set cell that known buildings do not hide from the final pose, m;
//! - `Φ_h`: area of the predicted sets at the end of the horizon inside ground hidden in the
//!   last `h` time steps (eq. 28), m².
//!
//! Sequences whose predicted positions leave the border square (the RoI by default) are
//! excluded; if every sequence leaves it, the one that strays least is taken. Ties keep the
//! first sequence in lexicographic order of the increments, so decisions are deterministic.
//!
//! The search is a branch and bound (`search`) that decides exactly as the plain enumeration:
//! sequences are costed in order of a lower bound (their sets predicted without shadows) and
//! the visit stops when no bound can beat the best cost.
//!
//! Where the paper can be read two ways, or the code once departed from it, a scenario key
//! chooses, and the defaults (the `paper`, `kappa0` and `nomap` variants) take the paper as
//! written:
//!
//! | key | default: the paper as written | other reading |
//! |---|---|---|
//! | `guidance.predicted_views` | `period_end`: the view `F^P_{k+τ}` at the pose ending each period removes ground (eqs. 29-30) | `every_frame`: the views of every CVS frame of the period, since the camera sees at every frame |
//! | `guidance.set_resolution` | `estimator`: the sets are predicted on the estimator's cells (0.5 m), so `Φ_X` is their exact area and `Φ_d` reaches the nearest of them (see "Exact counts" below) | `planning`: predicted on the coarse planning grid ([`coarse`](super::coarse), 2.5 m), a planning cell counted whole when any of its estimator cells is in a set |
//! | `guidance.distance_from` | `uav`: `Φ_d` from `p_g(x^u_{k+h})`, the UAV's predicted ground position at the end of the horizon | `view_centre`: from the ground point the camera's optical axis meets from the final pose ([`view::view_centre`]), what the camera looks at with a tilted gimbal |
//! | `guidance.hidden_sets` | `predicted`: `Φ_h` counts the predicted sets at the end of the horizon inside the recently hidden ground | `current`: it counts today's sets inside the recently hidden ground, where the predicted sets still hold them |
//! | `guidance.hidden_resolution` | `estimator`: `Φ_h` counts estimator cells, those in the sets (as `hidden_sets` chooses) *and* hidden; on planning cells, each predicted planning cell counts its hidden estimator cells ([`CellWeights`]), so the coarsening cannot invent an overlap | `planning`: a predicted planning cell counts whole when any of its estimator cells is hidden, even if none of them is in the sets |
//! | `guidance.hidden_window` | `frames`: eq. (28)'s "last `h` time steps" are CVS frames (the estimator's history, `estimator::HiddenHistory`) | `periods`: every frame of the last `h` guidance periods |
//! | `guidance.border` | `region`: sequences whose predicted positions leave the RoI are excluded; the world turns back a UAV that would cross its geofence ([`Scenario::geofence_half_extent`](protocol::scenario::Scenario::geofence_half_extent), 26 m inside the RoI by default), so a plan in the outer band may be overridden | `geofence`: plans stay inside the world's geofence, where the world never overrides a command, and the outer band is never planned over |
//!
//! With `hidden_resolution = "planning"`, `hidden_sets` changes nothing: a predicted planning
//! cell is counted whole when it holds hidden ground, which never looked at today's sets. With
//! `set_resolution = "estimator"` the planning cells it counts are those holding a predicted
//! estimator cell.
//!
//! # Exact counts
//!
//! `Φ_X` is the area of the predicted sets, and the sets are held on the estimator's cells. On
//! the planning grid a cell is in the predicted sets when any of its 25 estimator cells is,
//! and counts 6.25 m² where a single estimator cell of 0.25 m² may lie. One could carry, per
//! planning cell, a count of its estimator cells through the prediction, as `Φ_h` does with
//! [`CellWeights`]: a cell cleared by a view loses its count, and a cell the dilation reaches
//! needs one. But a count must stay sound, never below the estimator cells the targets can
//! reach (every area of the project is an upper bound of its set's), and then it saturates at
//! the first dilation: a period's growth (2 m/s x 3 s = 6 m by default) is larger than the
//! distance between any two estimator cells of one planning cell (0.5 m x hypot(3, 3) = 2.1 m
//! by the dilation's closed-square rule), so every estimator cell of a planning cell that held
//! any is reachable, and a planning cell newly reached by the planning grid's dilation can only
//! be counted whole, since where in it the reach ends depends on estimator cells the planning
//! grid no longer has. Keeping a cell's earlier count through the dilation would count less
//! than the targets can reach; counting whole gives the planning grid's areas back. So the
//! inflation lies in the prediction, not in its counting: the dilation and the edges of the
//! views are rounded out to planning cells.
//!
//! `set_resolution = "estimator"` therefore predicts on the estimator's grid itself
//! ([`CoarseGrid::identity`]): the union of the sets as the estimator holds them, dilated by
//! the same conservative disc ([`CellSet::dilate`]) on estimator cells, less the views
//! rasterised on estimator cells. `Φ_X` is its cell count times the cell area, `Φ_d` reaches
//! its nearest visible cell (searched by planning cells, which skips empty ground a block at a
//! time and finds the same minimum), and `Φ_h` counts its cells that are recently hidden:
//! exact for the paper's prediction at the resolution the sets are held, with no rounding but
//! the prediction's own. Up to the rasterisers' epsilons, the planning grid's prediction holds
//! every planning cell that holds a cell of the estimator grid's (its dilation reaches every
//! planning cell within the radius of one of its cells; a planning cell a view clears lies
//! wholly in the view and outside every shadow, so its estimator cells are cleared too), so
//! the planning grid's `Φ_X` is an upper bound of the exact one. The exact prediction costs
//! about ten times the time per decision (measured once on 12 decisions over 500 buildings:
//! 11 ms against 1 ms, half of it the dilations of estimator cells).

mod search;

use protocol::camera::CameraPose;
use protocol::scenario::{
    DistanceFrom, HiddenResolution, HiddenSets, PredictedViews, SetResolution,
};
use protocol::wire::PlannedView;
use sets::grid::GroundGrid;
use sets::math::{Point2, Point3};
use sets::raster::CellSet;

use super::view::{self, GroundPredictor, ObstacleCell};
use super::{CellWeights, CoarseGrid, Decision, GuidanceParams, PlanningInput};

/// Picks the best sequence of yaw increments (docs/design.md §4): the paper's MPC, by the
/// branch and bound of the `search` module.
pub fn plan(params: &GuidanceParams, input: &PlanningInput<'_>) -> Decision {
    search::plan(params, input)
}

/// The paper's readings of its ambiguities (the keys of the module docs' table).
impl GuidanceParams {
    /// The poses of one period (or its first `n` frames) whose views clear the predicted
    /// sets: every one, or the last one only (`F^P_{k+τ}` of the paper's eqs. 29-30).
    fn viewed<'p>(&self, poses: &'p [CameraPose]) -> &'p [CameraPose] {
        match self.predicted_views {
            PredictedViews::EveryFrame => poses,
            PredictedViews::PeriodEnd => poses.last().map_or(&[], std::slice::from_ref),
        }
    }

    /// The grids the paper's MPC predicts on (`guidance.set_resolution`): its predicted sets
    /// lie on `coarse`, the estimator's cells are `fine` (the same grid for `Estimator`).
    fn paper_grids(&self) -> CoarseGrid {
        match self.set_resolution {
            SetResolution::Estimator => CoarseGrid::identity(self.grids.fine),
            SetResolution::Planning => self.grids,
        }
    }

    /// The union of `sets` (on the estimator's grid) on the grid of the predicted sets.
    fn start_sets(&self, sets: &[&CellSet]) -> CellSet {
        let grids = self.paper_grids();
        let mut union = CellSet::empty(&grids.coarse);
        for s in sets {
            union.or_assign(&grids.downsample(s));
        }
        union
    }

    /// The recently hidden ground as `Φ_h` counts it in the predicted sets
    /// (`guidance.hidden_resolution`, `guidance.hidden_sets`; see the module docs).
    fn hidden_measure(&self, sets: &[&CellSet], hidden: &CellSet) -> HiddenMeasure {
        let grids = self.paper_grids();
        match (self.hidden_resolution, self.hidden_sets) {
            // Whole planning cells: a planning cell of the predicted sets counts when any of
            // its estimator cells is hidden, whatever today's sets hold there.
            (HiddenResolution::Planning, _) => match self.set_resolution {
                SetResolution::Planning => HiddenMeasure::Weights(CellWeights::whole(
                    self.grids.downsample(hidden),
                    self.grids.coarse.cell_area(),
                )),
                SetResolution::Estimator => HiddenMeasure::Blocks {
                    grids: self.grids,
                    hidden: self.grids.downsample(hidden),
                },
            },
            // Estimator cells in the predicted sets and hidden.
            (HiddenResolution::Estimator, HiddenSets::Predicted) => {
                HiddenMeasure::Weights(grids.weights(hidden))
            }
            // Estimator cells in today's sets and hidden, where the predicted sets still are.
            (HiddenResolution::Estimator, HiddenSets::Current) => {
                let mut overlap = CellSet::empty(&self.grids.fine);
                for set in sets {
                    overlap.or_assign(set);
                }
                overlap.and_assign(hidden);
                HiddenMeasure::Weights(grids.weights(&overlap))
            }
        }
    }

    /// The ground point `Φ_d` is measured from at the final pose `pose`
    /// (`guidance.distance_from`).
    fn distance_origin(&self, pose: &CameraPose) -> Point2 {
        match self.distance_from {
            DistanceFrom::Uav => Point2::new(pose.position.x, pose.position.y),
            DistanceFrom::ViewCentre => view::view_centre(&self.camera, pose),
        }
    }

    /// `Φ_d` of the predicted sets `sets` (on the predicted sets' grid) from the final pose
    /// `pose`: the distance from [`GuidanceParams::distance_origin`] to the nearest cell of
    /// `sets` whose centre the known buildings do not hide from the camera; 0 for empty sets.
    fn distance_term(&self, sets: &CellSet, pose: &CameraPose, obstacles: &[ObstacleCell]) -> f64 {
        let from = self.distance_origin(pose);
        match self.set_resolution {
            SetResolution::Planning => {
                nearest_visible_distance(&self.grids.coarse, sets, from, &pose.position, obstacles)
            }
            SetResolution::Estimator => {
                nearest_visible_fine(&self.grids, sets, from, &pose.position, obstacles)
            }
        }
    }
}

/// Recently hidden ground as `Φ_h` counts it inside a sequence's predicted sets.
#[derive(Clone, Debug)]
enum HiddenMeasure {
    /// A count per cell of the predicted sets' grid ([`CellWeights::area_in`]).
    Weights(CellWeights),
    /// Predicted sets on the estimator's grid measured in whole planning cells: a planning
    /// cell of `grids` counts when it holds a predicted cell and is in `hidden` (the any-cell
    /// coarsening of the hidden ground).
    Blocks {
        /// The estimator's grid and the planning grid.
        grids: CoarseGrid,
        /// The planning cells holding hidden ground.
        hidden: CellSet,
    },
}

impl HiddenMeasure {
    /// `Φ_h` of the predicted sets `sets`, m². Monotone: a subset of `sets` never counts
    /// more (the branch and bound's bounds rely on it).
    fn area_in(&self, sets: &CellSet) -> f64 {
        match self {
            Self::Weights(weights) => weights.area_in(sets),
            Self::Blocks { grids, hidden } => {
                grids.downsample(sets).intersection_count(hidden) as f64 * grids.coarse.cell_area()
            }
        }
    }
}

/// Ground of `relevant` seen in `period` by the UAVs that decided before (from their
/// predicted poses).
fn seen_by_others(
    params: &GuidanceParams,
    others: &[PlannedView],
    period: u32,
    obstacles: &[ObstacleCell],
    predictor: &mut GroundPredictor,
    relevant: &CellSet,
) -> CellSet {
    let grid = params.paper_grids().coarse;
    let mut seen = CellSet::empty(&grid);
    let per = params.steps_per_period as usize;
    let range = period as usize * per..(period as usize + 1) * per;
    for view in others {
        for pose in params.viewed(view.poses.get(range.clone()).unwrap_or(&[])) {
            if pose.position.iter().all(|v| v.is_finite()) && pose.yaw.is_finite() {
                predictor.add_visible_ground_within(
                    &mut seen,
                    &grid,
                    &params.camera,
                    pose,
                    obstacles,
                    relevant,
                );
            }
        }
    }
    seen
}

/// Distance from `from` to the nearest cell of `sets` (on `grid`) whose centre the known
/// buildings do not hide from `eye`, by rings of cells around `from`; 0 for an empty set.
fn nearest_visible_distance(
    grid: &GroundGrid,
    sets: &CellSet,
    from: Point2,
    eye: &Point3,
    obstacles: &[ObstacleCell],
) -> f64 {
    if sets.is_empty() {
        return 0.0;
    }
    let (cx, cy) = ring_centre(grid, from);
    let mut best = f64::INFINITY;
    let max_ring = grid.nx.max(grid.ny) as i64;
    for ring in 0..=max_ring {
        // Every cell of a later ring is at least this far from `from`.
        if best <= (ring as f64 - 0.75) * grid.cell_m {
            break;
        }
        for cell in ring_cells(cx, cy, ring).filter_map(|c| on_grid(grid, c)) {
            if sets.contains(cell) {
                best = closer_if_visible(best, grid.cell_centre(cell), from, eye, obstacles);
            }
        }
    }
    if best.is_finite() {
        best
    } else {
        all_hidden_distance(grid)
    }
}

/// [`nearest_visible_distance`] for sets on the estimator's grid `grids.fine`, by rings of
/// planning cells (`grids.coarse`) so that empty ground is skipped a block at a time: the
/// same value, the minimum over every visible cell of the sets.
///
/// A planning cell at Chebyshev ring `r` (in planning cells) from the one holding `from`
/// (or the nearest one, when `from` is off the grid) lies more than `(r - 1)` planning cells
/// away along one axis, so the visit stops once the best distance is no larger: no later
/// cell could be nearer.
fn nearest_visible_fine(
    grids: &CoarseGrid,
    sets: &CellSet,
    from: Point2,
    eye: &Point3,
    obstacles: &[ObstacleCell],
) -> f64 {
    if sets.is_empty() {
        return 0.0;
    }
    let (fine, coarse, f) = (&grids.fine, &grids.coarse, grids.factor);
    let blocks = grids.downsample(sets);
    let (cx, cy) = ring_centre(coarse, from);
    let mut best = f64::INFINITY;
    let max_ring = coarse.nx.max(coarse.ny) as i64;
    for ring in 0..=max_ring {
        if best <= (ring as f64 - 1.0) * coarse.cell_m {
            break;
        }
        for (x, y) in ring_cells(cx, cy, ring).filter_map(|c| on_grid(coarse, c)) {
            if !blocks.contains((x, y)) {
                continue;
            }
            for fy in y * f..((y + 1) * f).min(fine.ny) {
                for fx in x * f..((x + 1) * f).min(fine.nx) {
                    if sets.contains((fx, fy)) {
                        let p = fine.cell_centre((fx, fy));
                        best = closer_if_visible(best, p, from, eye, obstacles);
                    }
                }
            }
        }
    }
    if best.is_finite() {
        best
    } else {
        all_hidden_distance(fine)
    }
}

/// `Φ_d` when every cell of the sets is hidden: as far as anything can be on `grid`.
/// The cell of `grid` nearest `from` (clamped into the grid), where the rings start.
fn ring_centre(grid: &GroundGrid, from: Point2) -> (i64, i64) {
    let clamp = |v: f64, n: u32| v.clamp(0.0, n as f64 - 1.0) as i64;
    (
        clamp(((from.x - grid.origin.x) / grid.cell_m).floor(), grid.nx),
        clamp(((from.y - grid.origin.y) / grid.cell_m).floor(), grid.ny),
    )
}

/// Cell `(x, y)` of a ring, if it lies on `grid`.
fn on_grid(grid: &GroundGrid, (x, y): (i64, i64)) -> Option<(u32, u32)> {
    let inside = x >= 0 && y >= 0 && x < grid.nx as i64 && y < grid.ny as i64;
    inside.then_some((x as u32, y as u32))
}

/// `best`, or the distance from `from` to `p` when that is smaller and the known buildings do
/// not hide `p` from `eye`.
fn closer_if_visible(
    best: f64,
    p: Point2,
    from: Point2,
    eye: &Point3,
    obstacles: &[ObstacleCell],
) -> f64 {
    let d = (p - from).norm();
    if d < best && !view::hidden_by(eye, &p, obstacles) {
        d
    } else {
        best
    }
}

fn all_hidden_distance(grid: &GroundGrid) -> f64 {
    (grid.nx.max(grid.ny) as f64) * grid.cell_m * std::f64::consts::SQRT_2
}

/// The cells at Chebyshev distance `ring` from `(cx, cy)`.
fn ring_cells(cx: i64, cy: i64, ring: i64) -> impl Iterator<Item = (i64, i64)> {
    let side = if ring == 0 { 1 } else { 2 * ring + 1 };
    (0..side).flat_map(move |i| {
        let x = cx - ring + i;
        let top = (x, cy + ring);
        let bottom = (x, cy - ring);
        let edge = i == 0 || i == side - 1;
        let column: Box<dyn Iterator<Item = (i64, i64)>> = if ring == 0 {
            Box::new(std::iter::once((cx, cy)))
        } else if edge {
            Box::new((-ring..=ring).map(move |dy| (x, cy + dy)))
        } else {
            Box::new([top, bottom].into_iter())
        };
        column
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::guidance::tests::{Xorshift, fingerprint, scenario, turning, watching_the_south};
    use crate::guidance::{Cost, decision, fly_step, stray};
    use protocol::flight::UavState;
    use protocol::scenario::{PlanBorder, Scenario};
    use sets::grid::Rect;
    use sets::math::{Point2, Point3};
    use sets::raster::Coverage;

    fn blob(params: &GuidanceParams, centre: Point2, radius: f64) -> CellSet {
        let mut s = CellSet::empty(&params.grids.fine);
        s.fill_disc(&params.grids.fine, centre, radius, Coverage::Outer);
        s
    }

    fn start() -> UavState {
        UavState {
            position: Point3::new(0.0, 0.0, 60.0),
            yaw: 0.0,
        }
    }

    fn decide(
        params: &GuidanceParams,
        sets: &[&CellSet],
        obstacles: &[ObstacleCell],
        others: &[PlannedView],
    ) -> Decision {
        decide_from(params, start(), sets, obstacles, others)
    }

    /// UAV 1's decision from `state`, nothing recently hidden.
    fn decide_from(
        params: &GuidanceParams,
        state: UavState,
        sets: &[&CellSet],
        obstacles: &[ObstacleCell],
        others: &[PlannedView],
    ) -> Decision {
        let hidden = CellSet::empty(&params.grids.fine);
        plan(
            params,
            &PlanningInput {
                uav: 1,
                state,
                sets,
                recently_hidden: &hidden,
                unseen: &hidden,
                obstacles,
                others,
                fleet: &[],
            },
        )
    }

    #[test]
    fn turns_toward_the_unexplored_region() {
        let params = GuidanceParams::from_scenario(&scenario());
        let north = blob(&params, Point2::new(0.0, 80.0), 20.0);
        let d = decide(&params, &[&north], &[], &[]);
        assert!(d.increments[0] > 0.0, "{d:?}");
        let south = blob(&params, Point2::new(0.0, -80.0), 20.0);
        let d = decide(&params, &[&south], &[], &[]);
        assert!(d.increments[0] < 0.0, "{d:?}");
        assert_eq!(d.sequences, 25);
        assert_eq!(d.view.poses.len(), 12);
        assert!((d.yaw_ref - d.increments[0]).abs() < 1e-12);
    }

    #[test]
    fn leaves_to_the_uav_ahead_what_it_will_see() {
        let params = GuidanceParams::from_scenario(&scenario());
        let north = blob(&params, Point2::new(0.0, 80.0), 20.0);
        let south = blob(&params, Point2::new(0.0, -80.0), 20.0);
        // Without a plan ahead, the two blobs tie and the first sequence (turning right)
        // wins; with the UAV ahead watching the south blob, this one takes the north.
        let d = decide(&params, &[&north, &south], &[], &[watching_the_south()]);
        assert!(d.increments[0] > 0.0, "{d:?}");
    }

    #[test]
    fn is_not_drawn_to_a_set_hidden_behind_a_known_building() {
        let params = GuidanceParams::from_scenario(&scenario());
        let north = blob(&params, Point2::new(0.0, 80.0), 15.0);
        let south = blob(&params, Point2::new(0.0, -80.0), 15.0);
        // A wall of tall buildings just south of the north blob hides it from the UAV.
        let wall: Vec<ObstacleCell> = (-8..8)
            .map(|i| ObstacleCell {
                rect: Rect {
                    min: Point2::new(i as f64 * 5.0, 55.0),
                    max: Point2::new(i as f64 * 5.0 + 5.0, 60.0),
                },
                height_m: 55.0,
            })
            .collect();
        // Make the north blob slightly larger so that without the map it would win.
        let north_big = blob(&params, Point2::new(0.0, 80.0), 18.0);
        let d = decide(&params, &[&north_big, &south], &[], &[]);
        assert!(
            d.increments[0] > 0.0,
            "without the map the larger north blob wins: {d:?}"
        );
        let d = decide(&params, &[&north_big, &south], &wall, &[]);
        assert!(
            d.increments[0] < 0.0,
            "the hidden north blob must not attract: {d:?}"
        );
        let _ = north;
    }

    #[test]
    fn never_plans_out_of_the_region_when_it_can_stay() {
        let mut s = scenario();
        s.region.half_extent_m = 150.0;
        s.guidance.border = PlanBorder::Region;
        let params = GuidanceParams::from_scenario(&s);
        // Near the east border heading east: most sequences leave; the chosen one must not.
        let everything = CellSet::full(&params.grids.fine);
        let east = UavState {
            position: Point3::new(125.0, 0.0, 60.0),
            yaw: 0.0,
        };
        let d = decide_from(&params, east, &[&everything], &[], &[]);
        assert!(d.excluded > 0);
        assert!(
            d.view
                .poses
                .iter()
                .all(|p| p.position.x.abs() <= 150.0 && p.position.y.abs() <= 150.0)
        );
    }

    /// With `guidance.border = "geofence"`, heading at the fence, the chosen plan turns
    /// before it, so the world never has to override it.
    #[test]
    fn plans_stay_inside_the_world_geofence() {
        let mut s = scenario();
        s.guidance.border = PlanBorder::Geofence;
        let fence = s.geofence_half_extent();
        assert!(fence < s.region.half_extent_m);
        let params = GuidanceParams::from_scenario(&s);
        assert_eq!(params.region.max.x, fence);
        assert_eq!(params.region.min.y, -fence);
        let everything = CellSet::full(&params.grids.fine);
        let east = UavState {
            position: Point3::new(fence - 30.0, 0.0, 60.0),
            yaw: 0.0,
        };
        let d = decide_from(&params, east, &[&everything], &[], &[]);
        assert!(d.excluded > 0, "{d:?}");
        assert!(
            d.view
                .poses
                .iter()
                .all(|p| p.position.x.abs() <= fence && p.position.y.abs() <= fence),
            "{d:?}"
        );
    }

    /// The default border is the RoI, as the paper writes: one straight period east from
    /// x = 95 m ends at 95 + 6 x 5 = 125 m, inside the 150 m region (kept) but 1 m past the
    /// world's geofence at 150 - (2 x 10 / 1 + 10 x 0.5 + 1) = 124 m (excluded there).
    #[test]
    fn the_default_border_is_the_region() {
        let excluded = |border: Option<PlanBorder>| {
            let mut s = scenario();
            s.guidance.horizon = 1;
            s.guidance.yaw_increments_rad = vec![0.0];
            if let Some(b) = border {
                s.guidance.border = b;
            }
            let params = GuidanceParams::from_scenario(&s);
            let set = blob(&params, Point2::new(-100.0, -100.0), 3.0);
            let state = UavState {
                position: Point3::new(95.0, 0.25, 60.0),
                yaw: 0.0,
            };
            let d = decide_from(&params, state, &[&set], &[], &[]);
            assert_eq!(d.view.poses.last().unwrap().position.x, 125.0);
            (params.region.max.x, d.excluded)
        };
        assert_eq!(excluded(None), (150.0, 0));
        assert_eq!(excluded(Some(PlanBorder::Region)), (150.0, 0));
        assert_eq!(excluded(Some(PlanBorder::Geofence)), (124.0, 1));
    }

    /// The hand-computed case of the set keys: `U = {0}`, `h = 1`, a UAV at (-20, 0.25) m,
    /// 60 m up, flying east for one period to (10, 0.25), and one set of a single estimator
    /// cell, (219, 300), centred at (-40.25, 0.25), behind the UAV where no view reaches.
    /// Returns the decision's cost.
    fn single_cell_cost(configure: impl FnOnce(&mut Scenario), hidden: &[(u32, u32, u32)]) -> Cost {
        let mut s = scenario();
        s.guidance.horizon = 1;
        s.guidance.yaw_increments_rad = vec![0.0];
        configure(&mut s);
        let params = GuidanceParams::from_scenario(&s);
        let fine = params.grids.fine;
        let mut set = CellSet::empty(&fine);
        set.set((219, 300), true);
        assert_eq!(fine.cell_centre((219, 300)), Point2::new(-40.25, 0.25));
        let mut recently_hidden = CellSet::empty(&fine);
        for &(y, x0, x1) in hidden {
            recently_hidden.fill_row_span(y, x0, x1);
        }
        let d = plan(
            &params,
            &PlanningInput {
                uav: 1,
                state: UavState {
                    position: Point3::new(-20.0, 0.25, 60.0),
                    yaw: 0.0,
                },
                sets: &[&set],
                recently_hidden: &recently_hidden,
                unseen: &recently_hidden,
                obstacles: &[],
                others: &[],
                fleet: &[],
            },
        );
        let end = d.view.poses.last().unwrap().position;
        assert_eq!((end.x, end.y), (10.0, 0.25));
        d.cost
    }

    /// `guidance.set_resolution`, by hand. The period's growth is 2 m/s x 3 s = 6 m, and the
    /// dilation takes in a cell when `cell_m * hypot(max(|dx| - 1, 0), max(|dy| - 1, 0)) <= 6`.
    /// - `estimator` (0.5 m cells: `hypot(a, b) <= 12`): per column offset `a` (0 for
    ///   |dx| <= 1, then |dx| - 1), `b <= floor(sqrt(144 - a²))` = 12, 11, 11, 11, 11, 10, 10,
    ///   9, 8, 7, 6, 4, 0 for a = 0..=12, so columns of 3 + 2b cells: 3 x 27 + 2 x (25 x 4 +
    ///   23 x 2 + 21 + 19 + 17 + 15 + 11 + 3) = 545 cells, `Φ_X` = 545 x 0.25 = 136.25 m². The
    ///   nearest cell to the UAV's ground point (10, 0.25) is 13 columns east of the set's,
    ///   (232, 300), centred at (-33.75, 0.25): `Φ_d` = 43.75 m.
    /// - `planning` (2.5 m cells: `hypot(a, b) <= 2.4`): columns of 7, 7 and 5 cells for
    ///   a = 0, 1, 2: 3 x 7 + 2 x 7 + 2 x 5 = 45 cells, `Φ_X` = 45 x 6.25 = 281.25 m². The set's
    ///   planning cell is (43, 60); the nearest of the dilation to (10, 0.25) is (46, 60),
    ///   centred at (-33.75, 1.25): `Φ_d` = hypot(43.75, 1) m.
    #[test]
    fn set_resolution_by_hand() {
        let estimator = single_cell_cost(|_| {}, &[]);
        assert_eq!(estimator.area_m2, 545.0 * 0.25);
        assert_eq!(estimator.distance_m, 43.75);
        assert_eq!(estimator.hidden_m2, 0.0);
        let planning =
            single_cell_cost(|s| s.guidance.set_resolution = SetResolution::Planning, &[]);
        assert_eq!(planning.area_m2, 45.0 * 6.25);
        assert!(
            (planning.distance_m - 43.75_f64.hypot(1.0)).abs() < 1e-9,
            "{planning:?}"
        );
        assert_eq!(
            planning.total,
            planning.area_m2 + 1e-5 * planning.distance_m,
            "{planning:?}"
        );
    }

    /// `guidance.distance_from`, by hand, on the estimator's cells (the case of
    /// [`set_resolution_by_hand`]): from the UAV's ground point (10, 0.25) the nearest set cell,
    /// centred at (-33.75, 0.25), is 43.75 m away; from the view centre, 60 m ahead of a UAV
    /// 60 m up with the camera 45° below the horizon, (70, 0.25), it is 103.75 m away.
    #[test]
    fn distance_from_by_hand() {
        let uav = single_cell_cost(|s| s.guidance.distance_from = DistanceFrom::Uav, &[]);
        assert_eq!(uav.distance_m, 43.75);
        let centre = single_cell_cost(|s| s.guidance.distance_from = DistanceFrom::ViewCentre, &[]);
        assert!((centre.distance_m - 103.75).abs() < 1e-6, "{centre:?}");
    }

    /// `guidance.hidden_sets`, by hand (the case of [`set_resolution_by_hand`]): recently
    /// hidden ground on row 300, columns 220 to 240, which the set's one cell (column 219)
    /// does not meet but its predicted growth does (columns 206 to 232 on row 300).
    /// - `predicted`, estimator's cells: columns 220 to 232, 13 cells, 3.25 m².
    /// - `predicted`, planning cells with `hidden_resolution = "estimator"`: the predicted
    ///   planning cells of row 60 are columns 40 to 46, whose estimator columns 200 to 234 hold
    ///   hidden columns 220 to 234: 15 cells, 3.75 m².
    /// - `current`: today's set holds no hidden cell: 0.
    /// - `hidden_resolution = "planning"`, either set grid and either reading: planning cells
    ///   44 to 46 of row 60 are both predicted and hidden (hidden: 44 to 48), counted whole:
    ///   3 x 6.25 = 18.75 m².
    #[test]
    fn hidden_sets_by_hand() {
        let hidden = [(300, 220, 240)];
        let cost = |sets: SetResolution, which: HiddenSets, resolution: HiddenResolution| {
            single_cell_cost(
                |s| {
                    s.guidance.set_resolution = sets;
                    s.guidance.hidden_sets = which;
                    s.guidance.hidden_resolution = resolution;
                },
                &hidden,
            )
            .hidden_m2
        };
        use HiddenResolution as R;
        use HiddenSets::{Current, Predicted};
        use SetResolution::{Estimator, Planning};
        assert_eq!(single_cell_cost(|_| {}, &hidden).hidden_m2, 13.0 * 0.25);
        assert_eq!(cost(Estimator, Predicted, R::Estimator), 13.0 * 0.25);
        assert_eq!(cost(Planning, Predicted, R::Estimator), 15.0 * 0.25);
        assert_eq!(cost(Estimator, Current, R::Estimator), 0.0);
        assert_eq!(cost(Planning, Current, R::Estimator), 0.0);
        for sets in [Estimator, Planning] {
            for which in [Predicted, Current] {
                assert_eq!(cost(sets, which, R::Planning), 3.0 * 6.25);
            }
        }
    }

    /// The search by planning cells finds the very distance the plain minimum over every
    /// visible estimator cell of the sets does, from points on and off the grid.
    #[test]
    fn the_blocked_search_finds_the_nearest_visible_cell() {
        let params = GuidanceParams::from_scenario(&scenario());
        let fine = params.grids.fine;
        let mut rng = Xorshift(0x2545_f491_4f6c_dd1d);
        for case in 0..40 {
            let mut sets = CellSet::empty(&fine);
            for _ in 0..(case % 4) {
                sets.or_assign(&rng.disc(&fine, 150.0, 0.1, 20.0));
            }
            for _ in 0..(case % 7) {
                let cell = (
                    rng.uniform(0.0, fine.nx as f64) as u32,
                    rng.uniform(0.0, fine.ny as f64) as u32,
                );
                sets.set(cell, true);
            }
            let obstacles: Vec<ObstacleCell> =
                (0..(case * 5)).map(|_| rng.building(5.0, 80.0)).collect();
            let from = Point2::new(rng.uniform(-180.0, 180.0), rng.uniform(-180.0, 180.0));
            let eye = Point3::new(from.x, from.y, rng.uniform(20.0, 100.0));
            let plain = sets
                .iter()
                .map(|cell| fine.cell_centre(cell))
                .filter(|p| !view::hidden_by(&eye, p, &obstacles))
                .map(|p| (p - from).norm())
                .fold(f64::INFINITY, f64::min);
            let expected = if sets.is_empty() {
                0.0
            } else if plain.is_finite() {
                plain
            } else {
                all_hidden_distance(&fine)
            };
            let blocked = nearest_visible_fine(&params.grids, &sets, from, &eye, &obstacles);
            assert_eq!(blocked, expected, "case {case}");
        }
    }

    /// One straight sequence of one period (`U = {0}`, `h = 1`) past a small set that only
    /// the period's first frames see: with a view at every frame the set is cleared, with
    /// the view at the period's end only (the paper's `F^P_{k+τ}`) it is not.
    #[test]
    fn only_the_period_end_view_clears_the_sets_by_default() {
        let cost = |views: PredictedViews| {
            let mut s = scenario();
            s.guidance.horizon = 1;
            s.guidance.yaw_increments_rad = vec![0.0];
            s.guidance.predicted_views = views;
            let params = GuidanceParams::from_scenario(&s);
            let set = blob(&params, Point2::new(50.0, 0.0), 2.0);
            decide(&params, &[&set], &[], &[]).cost
        };
        let every_frame = cost(PredictedViews::EveryFrame);
        let period_end = cost(PredictedViews::PeriodEnd);
        assert_eq!(every_frame.area_m2, 0.0, "{every_frame:?}");
        // From 60 m up, the first frame's view starts 31.5 m ahead of the UAV, the last
        // frame's 25 m further on: the disc grown by one period (2 m + 6 m, on 2.5 m cells)
        // lies between the two near edges.
        assert!(period_end.area_m2 > 150.0, "{period_end:?}");
    }

    /// `Φ_h` at the estimator's resolution is the fine area of the sets' hidden ground (far
    /// from every view, so nothing clears it), and hidden ground sharing only coarse cells
    /// with the sets counts nothing; the any-cell coarsening counts both whole coarse cells.
    #[test]
    fn phi_h_counts_the_fine_overlap_of_the_sets_and_the_hidden_ground() {
        let hidden_m2 = |resolution: HiddenResolution| {
            let mut s = Scenario::default();
            s.guidance.hidden_resolution = resolution;
            // Today's sets, on the planning grid (the readings this test was written for).
            s.guidance.hidden_sets = HiddenSets::Current;
            s.guidance.set_resolution = SetResolution::Planning;
            s.guidance.kappa = 1.0;
            let params = GuidanceParams::from_scenario(&s);
            let fine = params.grids.fine;
            // The set: fine cells x in [0, 40), y in [0, 3) (a 20 m x 1.5 m strip in the
            // south-west corner) and the cell (100, 0); hidden: x in [20, 60), y in [0, 2),
            // and x in [100, 110), y in [3, 5) (coarse cells the set touches, but none of its
            // fine cells).
            let mut set = CellSet::empty(&fine);
            let mut hidden = CellSet::empty(&fine);
            for y in 0..3 {
                set.fill_row_span(y, 0, 39);
            }
            for y in 0..2 {
                hidden.fill_row_span(y, 20, 59);
            }
            for y in 3..5 {
                hidden.fill_row_span(y, 100, 109);
            }
            set.set((100, 0), true);
            let overlap = {
                let mut o = set.clone();
                o.and_assign(&hidden);
                o.count() as f64 * fine.cell_area()
            };
            let d = plan(
                &params,
                &PlanningInput {
                    uav: 0,
                    state: UavState {
                        position: Point3::new(100.0, 100.0, 80.0),
                        yaw: std::f64::consts::FRAC_PI_4,
                    },
                    sets: &[&set],
                    recently_hidden: &hidden,
                    unseen: &hidden,
                    obstacles: &[],
                    others: &[],
                    fleet: &[],
                },
            );
            (d.cost.hidden_m2, overlap)
        };
        let (fine_m2, overlap) = hidden_m2(HiddenResolution::Estimator);
        // Rows 0 and 1, x in [20, 40): 40 cells of 0.25 m².
        assert_eq!(overlap, 40.0 * 0.25);
        assert_eq!(fine_m2, overlap);
        let (coarse_m2, _) = hidden_m2(HiddenResolution::Planning);
        assert!(coarse_m2 > fine_m2, "{coarse_m2} <= {fine_m2}");
    }

    /// A random situation owned: the sets, the recently hidden ground, the known buildings,
    /// the plans ahead and the deciding UAV's state.
    struct Situation {
        sets: Vec<CellSet>,
        hidden: CellSet,
        obstacles: Vec<ObstacleCell>,
        others: Vec<PlannedView>,
        state: UavState,
    }

    impl Situation {
        /// A situation drawn from a xorshift stream seeded with `seed`: a few discs of
        /// undetected ground, up to two targets' sets, up to 200 buildings, up to three plans
        /// ahead, and a UAV anywhere in the region (near its border too).
        fn random(params: &GuidanceParams, seed: u64) -> Self {
            let mut rng = Xorshift(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
            let fine = &params.grids.fine;
            let mut undetected = CellSet::empty(fine);
            for _ in 0..rng.uniform(0.0, 6.0) as usize {
                undetected.or_assign(&rng.disc(fine, 150.0, 5.0, 60.0));
            }
            let mut sets = vec![undetected];
            for _ in 0..rng.uniform(0.0, 3.0) as usize {
                sets.push(rng.disc(fine, 150.0, 2.0, 15.0));
            }
            let hidden = rng.disc(fine, 150.0, 0.0, 50.0);
            let obstacles = (0..rng.uniform(0.0, 200.0) as usize)
                .map(|_| rng.building(5.0, 80.0))
                .collect();
            let planned_ahead = rng.uniform(0.0, 4.0) as u32;
            let mut flown = || {
                let start = UavState {
                    position: Point3::new(
                        rng.uniform(-145.0, 145.0),
                        rng.uniform(-145.0, 145.0),
                        rng.uniform(40.0, 100.0),
                    ),
                    yaw: rng.uniform(-3.2, 3.2),
                };
                (start, turning(start, rng.uniform(-1.0, 1.0)).1)
            };
            let others = (0..planned_ahead)
                .map(|uav| PlannedView {
                    uav,
                    poses: flown().1,
                })
                .collect();
            let state = flown().0;
            Self {
                sets,
                hidden,
                obstacles,
                others,
                state,
            }
        }
    }

    /// The paper's MPC as docs/design.md §4 states it, with nothing shared or skipped: every
    /// sequence of `U^h` in lexicographic order simulated from the start, every predicted
    /// view rasterised on the whole grid, every cost computed in full.
    fn plan_exhaustive(params: &GuidanceParams, input: &PlanningInput<'_>) -> Decision {
        let grid = params.paper_grids().coarse;
        let start_sets = params.start_sets(input.sets);
        let obstacles: &[ObstacleCell] = if params.use_map { input.obstacles } else { &[] };
        let hidden = params.hidden_measure(input.sets, input.recently_hidden);
        let per = params.steps_per_period as usize;
        let others_seen: Vec<CellSet> = (0..params.horizon as usize)
            .map(|period| {
                let mut seen = CellSet::empty(&grid);
                for v in input.others {
                    let poses = v.poses.get(period * per..(period + 1) * per).unwrap_or(&[]);
                    for pose in params.viewed(poses) {
                        view::add_visible_ground(&mut seen, &grid, &params.camera, pose, obstacles);
                    }
                }
                seen
            })
            .collect();
        let period_s = params.steps_per_period as f64 * params.dt;
        let n = params.increments.len();
        let h = params.horizon as usize;
        // The best so far: (stray, J), its cost, increments and poses.
        type Best = ((f64, f64), Cost, Vec<f64>, Vec<CameraPose>);
        let mut best: Option<Best> = None;
        let (mut sequences, mut excluded) = (0, 0);
        for index in 0..n.pow(h as u32) {
            // The digits of `index` in base |U|, the first period's the most significant.
            let increments: Vec<f64> = (0..h)
                .map(|p| params.increments[index / n.pow((h - 1 - p) as u32) % n])
                .collect();
            let mut state = input.state;
            let mut sets = start_sets.clone();
            let mut poses = Vec::new();
            let mut stray_m = 0.0_f64;
            for (period, u) in increments.iter().enumerate() {
                sets = sets.dilate(&grid, params.target_max_speed * period_s);
                sets.and_not_assign(&others_seen[period]);
                let yaw_ref = state.yaw + u;
                let mut seen = CellSet::empty(&grid);
                let start = poses.len();
                for _ in 0..per {
                    let pose;
                    (state, pose) = fly_step(params, state, yaw_ref);
                    stray_m = stray_m.max(stray(&params.region, &state.position));
                    poses.push(pose);
                }
                for pose in params.viewed(&poses[start..]) {
                    view::add_visible_ground(&mut seen, &grid, &params.camera, pose, obstacles);
                }
                sets.and_not_assign(&seen);
            }
            sequences += 1;
            if stray_m > 0.0 {
                excluded += 1;
            }
            let area_m2 = sets.count() as f64 * grid.cell_area();
            let hidden_m2 = hidden.area_in(&sets);
            let distance_m = poses
                .last()
                .map_or(0.0, |pose| params.distance_term(&sets, pose, obstacles));
            let cost = Cost {
                area_m2,
                distance_m,
                hidden_m2,
                total: area_m2 + params.lambda * distance_m + params.kappa * hidden_m2,
            };
            let key = (stray_m, cost.total);
            if best.as_ref().is_none_or(|(b, ..)| key < *b) {
                best = Some((key, cost, increments, poses));
            }
        }
        decision(
            input,
            best.map(|(_, cost, increments, poses)| (increments, cost, poses)),
            sequences,
            excluded,
        )
    }

    /// The optimised search (prefix sharing, views predicted on the sets' ground only,
    /// `Φ_d` bounded) decides exactly as the plain enumeration of every sequence: the same
    /// increments, cost, plan and counts, bit for bit, in random situations with and without
    /// the map, for several weights and horizons, under every reading of the module docs'
    /// table (each key's two readings alternate with a period of their own, so that the
    /// readings meet in many combinations).
    #[test]
    fn the_search_decides_as_the_plain_enumeration() {
        for seed in 0..128u64 {
            let mut s = scenario();
            s.guidance.lambda = [1.0, 0.0, 25.0, 200.0][seed as usize % 4];
            s.guidance.kappa = [1.0, 0.0, 3.0][seed as usize % 3];
            s.guidance.use_map = seed % 5 != 4;
            if seed % 8 == 7 {
                s.guidance.horizon = 3;
                s.guidance.yaw_increments_rad = vec![-0.6, 0.0, 0.6];
            }
            // Every reading of the paper's ambiguities, in turn.
            s.guidance.predicted_views =
                [PredictedViews::PeriodEnd, PredictedViews::EveryFrame][seed as usize % 2];
            s.guidance.hidden_resolution =
                [HiddenResolution::Estimator, HiddenResolution::Planning][seed as usize / 2 % 2];
            s.guidance.border = [PlanBorder::Region, PlanBorder::Geofence][seed as usize / 4 % 2];
            s.guidance.set_resolution =
                [SetResolution::Estimator, SetResolution::Planning][seed as usize / 3 % 2];
            s.guidance.distance_from =
                [DistanceFrom::Uav, DistanceFrom::ViewCentre][seed as usize / 5 % 2];
            s.guidance.hidden_sets =
                [HiddenSets::Predicted, HiddenSets::Current][seed as usize / 7 % 2];
            let params = GuidanceParams::from_scenario(&s);
            let situation = Situation::random(&params, seed);
            let sets: Vec<&CellSet> = situation.sets.iter().collect();
            let input = PlanningInput {
                uav: 9,
                state: situation.state,
                sets: &sets,
                recently_hidden: &situation.hidden,
                unseen: &situation.hidden,
                obstacles: &situation.obstacles,
                others: &situation.others,
                fleet: &[],
            };
            let fast = plan(&params, &input);
            let reference = plan_exhaustive(&params, &input);
            assert_eq!(fingerprint(&fast), fingerprint(&reference), "seed {seed}");
            assert_eq!(fast, reference, "seed {seed}");
        }
    }
}
