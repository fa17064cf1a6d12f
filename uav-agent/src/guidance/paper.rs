//! The paper's MPC (docs/design.md §4; the paper's Sections VI-VII): the `paper` planner.
//!
//! For every sequence of yaw increments in `U^h`, the UAV's own states are predicted with the
//! world's dynamics ([`protocol::flight::advance`]) at every CVS step of the horizon; the
//! predicted sets (the union of `X̄` and every `X_j`, on the coarse planning grid of
//! [`coarse`](super::coarse)) are dilated by the targets' motion once per guidance period and
//! lose the ground the UAV will see in that period (its predicted field of view less the
//! shadows of known buildings, [`view`]) and the ground seen by the UAVs that already decided
//! this round (the token). The sequence minimising `J = Φ_X + λ Φ_d + κ Φ_h` wins:
//! - `Φ_X`: area of the predicted sets at the end of the horizon, m²;
//! - `Φ_d`: distance from the predicted view centre to the nearest predicted set cell that
//!   known buildings do not hide from the final pose, m;
//! - `Φ_h`: area of the predicted sets inside ground hidden in the last `h` time steps
//!   (eq. 28), m².
//!
//! Sequences whose predicted positions leave the border square are excluded; if every sequence
//! leaves it, the one that strays least is taken. Ties keep the first sequence in lexicographic
//! order of the increments, so decisions are deterministic.
//!
//! The search is a branch and bound (`search`) that decides exactly as the plain enumeration:
//! sequences are costed in order of a lower bound (their sets predicted without shadows) and
//! the visit stops when no bound can beat the best cost.
//!
//! Where the paper can be read two ways, a scenario key chooses, and the defaults (the `paper`
//! variant) take the literal reading:
//!
//! | key | default: the paper as written | other reading |
//! |---|---|---|
//! | `guidance.predicted_views` | `period_end`: the view `F^P_{k+τ}` at the pose ending each period removes ground (eqs. 29-30) | `every_frame`: the views of every CVS frame of the period, since the camera sees at every frame |
//! | `guidance.hidden_resolution` | `estimator`: `Φ_h` counts, in each predicted coarse cell, the area of its 0.5 m cells that are in the sets *and* hidden now ([`CellWeights`]), so the coarsening cannot invent an overlap | `planning`: a predicted coarse cell counts whole when any of its fine cells is hidden, even if none of them is in the sets |
//! | `guidance.hidden_window` | `frames`: eq. (28)'s "last `h` time steps" are CVS frames (the estimator's history, `estimator::HiddenHistory`) | `periods`: every frame of the last `h` guidance periods |
//! | `guidance.border` | `geofence`: plans stay inside the world's geofence ([`Scenario::geofence_half_extent`](protocol::scenario::Scenario::geofence_half_extent)), where the world never overrides a command | `region`: plans stay inside the RoI, and the world turns back those that cross its geofence |
//!
//! `Φ_h` at the estimator's resolution counts the sets' hidden ground where the sets are now;
//! ground the sets grow into over the horizon is counted by `Φ_X` only (on the planning grid
//! the two cannot be told apart from an invented overlap). `Φ_d` is measured from the point the
//! optical axis meets the ground, which is what the camera looks at with a tilted gimbal.

mod search;

use protocol::camera::{CameraModel, CameraPose};
use protocol::scenario::{HiddenResolution, PredictedViews};
use protocol::wire::PlannedView;
use sets::grid::GroundGrid;
use sets::raster::CellSet;

use super::view::{self, GroundPredictor, ObstacleCell};
use super::{CellWeights, Decision, GuidanceParams, PlanningInput};

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

    /// The recently hidden ground as `Φ_h` counts it on the planning grid
    /// (`guidance.hidden_resolution`): per coarse cell, the area of its fine cells in both
    /// `sets` and `hidden` (`Estimator`), or the whole cell when any fine cell is hidden
    /// (`Planning`).
    fn hidden_weights(&self, sets: &[&CellSet], hidden: &CellSet) -> CellWeights {
        match self.hidden_resolution {
            HiddenResolution::Planning => CellWeights::whole(
                self.grids.downsample(hidden),
                self.planning_grid().cell_area(),
            ),
            HiddenResolution::Estimator => {
                let mut overlap = CellSet::empty(&self.grids.fine);
                for set in sets {
                    overlap.or_assign(set);
                }
                overlap.and_assign(hidden);
                self.grids.weights(&overlap)
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
    let grid = *params.planning_grid();
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

/// Distance from the view centre of `pose` to the nearest cell of `sets` whose centre the
/// known buildings do not hide from the camera; 0 for an empty set.
fn nearest_visible_distance(
    grid: &GroundGrid,
    sets: &CellSet,
    camera: &CameraModel,
    pose: &CameraPose,
    obstacles: &[ObstacleCell],
) -> f64 {
    if sets.is_empty() {
        return 0.0;
    }
    let centre = view::view_centre(camera, pose);
    let clamp = |v: f64, n: u32| v.clamp(0.0, n as f64 - 1.0) as i64;
    let cx = clamp(((centre.x - grid.origin.x) / grid.cell_m).floor(), grid.nx);
    let cy = clamp(((centre.y - grid.origin.y) / grid.cell_m).floor(), grid.ny);
    let mut best = f64::INFINITY;
    let max_ring = grid.nx.max(grid.ny) as i64;
    for ring in 0..=max_ring {
        // Every cell of a later ring is at least this far from the centre.
        if best <= (ring as f64 - 0.75) * grid.cell_m {
            break;
        }
        for (x, y) in ring_cells(cx, cy, ring) {
            if x < 0 || y < 0 || x >= grid.nx as i64 || y >= grid.ny as i64 {
                continue;
            }
            let cell = (x as u32, y as u32);
            if !sets.contains(cell) {
                continue;
            }
            let p = grid.cell_centre(cell);
            let d = (p - centre).norm();
            if d < best && !view::hidden_by(&pose.position, &p, obstacles) {
                best = d;
            }
        }
    }
    if best.is_finite() {
        best
    } else {
        // Every set cell is hidden: as far as anything can be on the grid.
        (grid.nx.max(grid.ny) as f64) * grid.cell_m * std::f64::consts::SQRT_2
    }
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

    /// The default border is the world's geofence: heading at it, the chosen plan turns
    /// before the fence, so the world never has to override it.
    #[test]
    fn plans_stay_inside_the_world_geofence() {
        let s = scenario();
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
        let grid = *params.planning_grid();
        let mut start_sets = CellSet::empty(&grid);
        for s in input.sets {
            start_sets.or_assign(&params.grids.downsample(s));
        }
        let obstacles: &[ObstacleCell] = if params.use_map { input.obstacles } else { &[] };
        let hidden = params.hidden_weights(input.sets, input.recently_hidden);
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
            let distance_m = poses.last().map_or(0.0, |pose| {
                nearest_visible_distance(&grid, &sets, &params.camera, pose, obstacles)
            });
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
    /// the map, for several weights and horizons.
    #[test]
    fn the_search_decides_as_the_plain_enumeration() {
        for seed in 0..48u64 {
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
            s.guidance.border = [PlanBorder::Geofence, PlanBorder::Region][seed as usize / 4 % 2];
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
