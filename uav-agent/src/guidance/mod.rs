//! Guidance: one decision per guidance period, by the planner `guidance.planner` names.
//!
//! - `paper` (the default): the MPC of docs/design.md §4 as the paper writes it, [`plan`], below.
//!   The `paper` variant runs it untouched.
//! - `setfleet`: the project's own planner, [`setfleet::plan`]: a beam search over longer
//!   sequences that values the future growth of unobserved sets (see its docs).
//!
//! [`decide`] picks between them. The rest of this page is the paper's MPC.
//!
//! For every sequence of yaw increments in `U^h`, the UAV's own states are predicted with the
//! world's dynamics ([`protocol::flight::advance`]) at every CVS step of the horizon; the
//! predicted sets (the union of `X̄` and every `X_j`, on the coarse planning grid of
//! [`coarse`]) are dilated by the targets' motion once per guidance period and lose the ground
//! the UAV will see in that period (its predicted field of view less the shadows of known
//! buildings, [`view`]) and the ground seen by the UAVs that already decided this round (the
//! token). The sequence minimising `J = Φ_X + λ Φ_d + κ Φ_h` wins:
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
//! | `guidance.border` | `geofence`: plans stay inside the world's geofence ([`Scenario::geofence_half_extent`]), where the world never overrides a command | `region`: plans stay inside the RoI, and the world turns back those that cross its geofence |
//!
//! `Φ_h` at the estimator's resolution counts the sets' hidden ground where the sets are now;
//! ground the sets grow into over the horizon is counted by `Φ_X` only (on the planning grid
//! the two cannot be told apart from an invented overlap). `Φ_d` is measured from the point the
//! optical axis meets the ground, which is what the camera looks at with a tilted gimbal.

pub mod coarse;
pub mod ring;
mod search;
pub mod setfleet;
pub mod view;

use protocol::camera::{CameraModel, CameraPose};
use protocol::flight::{self, UavState};
use protocol::grid::{GroundGrid, Rect};
use protocol::math::{Point2, Point3};
use protocol::raster::CellSet;
use protocol::scenario::{HiddenResolution, PlanBorder, Planner, PredictedViews, Scenario};
use protocol::wire::PlannedView;

pub use coarse::{CellWeights, CoarseGrid};
pub use ring::{TokenRing, Turn};
pub use setfleet::SetfleetParams;
pub use view::{GroundPredictor, ObstacleCell};

/// Everything about the MPC that does not change during a run.
#[derive(Clone, Debug)]
pub struct GuidanceParams {
    /// Estimator grid and planning grid.
    pub grids: CoarseGrid,
    /// The camera.
    pub camera: CameraModel,
    /// The square plans must stay in (`guidance.border`): the world's geofence or the RoI.
    pub region: Rect,
    /// Horizon `h`, guidance periods.
    pub horizon: u32,
    /// The yaw increments `U`, radians.
    pub increments: Vec<f64>,
    /// Weight of `Φ_d`.
    pub lambda: f64,
    /// Weight of `Φ_h`.
    pub kappa: f64,
    /// Whether the occupancy map's buildings hide ground in predictions.
    pub use_map: bool,
    /// How `Φ_h` measures the sets inside hidden ground (`guidance.hidden_resolution`).
    pub hidden_resolution: HiddenResolution,
    /// Which predicted poses' views clear the predicted sets (`guidance.predicted_views`).
    pub predicted_views: PredictedViews,
    /// CVS steps per guidance period.
    pub steps_per_period: u32,
    /// CVS period, seconds.
    pub dt: f64,
    /// UAV ground speed, m/s.
    pub speed: f64,
    /// UAV yaw-rate bound, rad/s.
    pub max_yaw_rate: f64,
    /// Targets' speed bound, m/s.
    pub target_max_speed: f64,
    /// Which planner [`decide`] runs.
    pub planner: Planner,
    /// The `setfleet` planner's settings (unused by the paper's MPC).
    pub setfleet: SetfleetParams,
    /// Whether the `setfleet` planner shares its work with rayon's thread pool (whose size
    /// `RAYON_NUM_THREADS` sets; the machine's cores by default). Decisions do not depend on
    /// it. While one UAV plans, the others of a lockstep round wait for the token, so the
    /// cores are free.
    pub parallel: bool,
}

impl GuidanceParams {
    /// The MPC of a scenario.
    pub fn from_scenario(s: &Scenario) -> Self {
        let h = match s.guidance.border {
            PlanBorder::Geofence => s.geofence_half_extent(),
            PlanBorder::Region => s.region.half_extent_m,
        };
        Self {
            grids: CoarseGrid::new(s.grid()),
            camera: s.camera_model(),
            region: Rect {
                min: Point2::new(-h, -h),
                max: Point2::new(h, h),
            },
            horizon: s.guidance.horizon,
            increments: s.guidance.yaw_increments_rad.clone(),
            lambda: s.guidance.lambda,
            kappa: s.guidance.kappa,
            use_map: s.guidance.use_map,
            hidden_resolution: s.guidance.hidden_resolution,
            predicted_views: s.guidance.predicted_views,
            steps_per_period: s.steps_per_guidance() as u32,
            dt: s.timing.cvs_period_s,
            speed: s.uavs.speed_mps,
            max_yaw_rate: s.uavs.max_yaw_rate_rps,
            target_max_speed: s.targets.max_speed_mps,
            planner: s.guidance.planner,
            setfleet: SetfleetParams {
                lookahead_periods: s.guidance.lookahead_periods,
                beam_width: s.guidance.beam_width,
                target_weight: s.guidance.target_weight,
                growth_horizon_s: s.guidance.growth_horizon_s,
                spread_m: s.guidance.spread_m,
            },
            parallel: true,
        }
    }

    fn planning_grid(&self) -> &GroundGrid {
        &self.grids.coarse
    }

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

/// What one decision looks at.
#[derive(Clone, Copy, Debug)]
pub struct PlanningInput<'a> {
    /// The deciding UAV.
    pub uav: u32,
    /// Its state now (camera optical centre and yaw).
    pub state: UavState,
    /// `X̄` and every `X_j`, on the estimator's grid.
    pub sets: &'a [&'a CellSet],
    /// Ground occluded in the last periods, on the estimator's grid.
    pub recently_hidden: &'a CellSet,
    /// Known buildings (ignored unless `use_map`).
    pub obstacles: &'a [ObstacleCell],
    /// Plans of the UAVs that decided before this one in the round.
    pub others: &'a [PlannedView],
}

/// The terms of the cost of a sequence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cost {
    /// `Φ_X`, m².
    pub area_m2: f64,
    /// `Φ_d`, m.
    pub distance_m: f64,
    /// `Φ_h`, m².
    pub hidden_m2: f64,
    /// `J`.
    pub total: f64,
}

/// The outcome of one decision.
#[derive(Clone, Debug, PartialEq)]
pub struct Decision {
    /// The chosen increments, one per period of the horizon.
    pub increments: Vec<f64>,
    /// The yaw reference to send now: current yaw plus the first increment.
    pub yaw_ref: f64,
    /// The chosen sequence's cost.
    pub cost: Cost,
    /// The plan to append to the token.
    pub view: PlannedView,
    /// Sequences evaluated.
    pub sequences: usize,
    /// Sequences excluded for leaving the RoI.
    pub excluded: usize,
}

/// One decision by the planner of `params` (`guidance.planner`).
pub fn decide(params: &GuidanceParams, input: &PlanningInput<'_>) -> Decision {
    match params.planner {
        Planner::Paper => plan(params, input),
        Planner::Setfleet => setfleet::plan(params, input),
    }
}

/// Picks the best sequence of yaw increments (docs/design.md §4): the paper's MPC, by the
/// branch and bound of the `search` module.
pub fn plan(params: &GuidanceParams, input: &PlanningInput<'_>) -> Decision {
    search::plan(params, input)
}

/// The decision for the best sequence found (increments, cost, poses), or holding the yaw
/// when there was none (only when `U` is empty; the scenario refuses that, but stay total).
fn decision(
    input: &PlanningInput<'_>,
    best: Option<(Vec<f64>, Cost, Vec<CameraPose>)>,
    sequences: usize,
    excluded: usize,
) -> Decision {
    let (increments, cost, poses) = best.unwrap_or((
        Vec::new(),
        Cost {
            area_m2: 0.0,
            distance_m: 0.0,
            hidden_m2: 0.0,
            total: 0.0,
        },
        Vec::new(),
    ));
    Decision {
        yaw_ref: input.state.yaw + increments.first().copied().unwrap_or(0.0),
        increments,
        cost,
        view: PlannedView {
            uav: input.uav,
            poses,
        },
        sequences,
        excluded,
    }
}

/// How far outside the region a position is, metres (0 inside).
/// One CVS step of the UAV's predicted flight toward `yaw_ref` (the world's dynamics): its new
/// state and camera pose.
fn fly_step(params: &GuidanceParams, state: UavState, yaw_ref: f64) -> (UavState, CameraPose) {
    let state = flight::advance(state, yaw_ref, params.dt, params.speed, params.max_yaw_rate);
    let pose = CameraPose {
        position: state.position,
        yaw: state.yaw,
    };
    (state, pose)
}

fn stray(region: &Rect, p: &Point3) -> f64 {
    let dx = (region.min.x - p.x).max(p.x - region.max.x).max(0.0);
    let dy = (region.min.y - p.y).max(p.y - region.max.y).max(0.0);
    dx.max(dy)
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
    use protocol::flight;
    use protocol::raster::Coverage;

    fn scenario() -> Scenario {
        let mut s = Scenario::default();
        s.region.half_extent_m = 150.0;
        s
    }

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

    /// A fixed xorshift stream, for test situations that stay the same on every machine.
    struct Xorshift(u64);

    impl Xorshift {
        /// Uniform in [lo, hi).
        fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
            let s = &mut self.0;
            *s ^= *s << 13;
            *s ^= *s >> 7;
            *s ^= *s << 17;
            lo + (hi - lo) * (*s >> 11) as f64 / (1u64 << 53) as f64
        }

        /// A disc of `grid` centred in the square of half side `half` (metres), of radius in
        /// [lo, hi).
        fn disc(&mut self, grid: &GroundGrid, half: f64, lo: f64, hi: f64) -> CellSet {
            let (x, y, r) = (
                self.uniform(-half, half),
                self.uniform(-half, half),
                self.uniform(lo, hi),
            );
            let mut d = CellSet::empty(grid);
            d.fill_disc(grid, Point2::new(x, y), r, Coverage::Outer);
            d
        }

        /// A building on one 5 m cell of the OEM within 150 m of the centre, of height in
        /// [lo, hi).
        fn building(&mut self, lo: f64, hi: f64) -> ObstacleCell {
            let (x, y) = (
                self.uniform(-30.0, 30.0).floor() * 5.0,
                self.uniform(-30.0, 30.0).floor() * 5.0,
            );
            ObstacleCell {
                rect: Rect {
                    min: Point2::new(x, y),
                    max: Point2::new(x + 5.0, y + 5.0),
                },
                height_m: self.uniform(lo, hi),
            }
        }
    }

    /// The 12 poses (0.5 s apart, 10 m/s) of a UAV turning by `turn` from `state`, and its
    /// state after them.
    fn turning(mut state: UavState, turn: f64) -> (UavState, Vec<CameraPose>) {
        let poses = (0..12)
            .map(|_| {
                state = flight::advance(state, state.yaw + turn, 0.5, 10.0, 1.0);
                CameraPose {
                    position: state.position,
                    yaw: state.yaw,
                }
            })
            .collect();
        (state, poses)
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
                obstacles,
                others,
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

    /// The plan of a UAV ahead in the token hovering south of the centre and looking south,
    /// for 12 steps.
    pub(super) fn watching_the_south() -> PlannedView {
        PlannedView {
            uav: 0,
            poses: (0..12)
                .map(|_| CameraPose {
                    position: Point3::new(0.0, -20.0, 70.0),
                    yaw: -std::f64::consts::FRAC_PI_2,
                })
                .collect(),
        }
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
                    obstacles: &[],
                    others: &[],
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

    /// A fingerprint of everything a decision holds (FNV-1a over the bits of its numbers).
    fn fingerprint(d: &Decision) -> u64 {
        let c = &d.cost;
        let numbers =
            d.increments
                .iter()
                .copied()
                .chain([d.yaw_ref, c.area_m2, c.distance_m, c.hidden_m2, c.total])
                .map(f64::to_bits)
                .chain(d.view.poses.iter().flat_map(|p| {
                    [p.position.x, p.position.y, p.position.z, p.yaw].map(f64::to_bits)
                }))
                .chain([u64::from(d.view.uav), d.sequences as u64, d.excluded as u64]);
        numbers.fold(0xcbf2_9ce4_8422_2325_u64, |h, w| {
            (h ^ w).wrapping_mul(0x100_0000_01b3)
        })
    }

    /// Decisions of both planners on busy inputs (sets, buildings, plans ahead) are the very
    /// ones recorded: a change meant only to make the planners faster must keep every bit of
    /// every decision. (A change of what the planners decide updates the fingerprints.)
    #[test]
    fn decisions_are_the_recorded_ones() {
        // The readings these fingerprints were recorded with, before the paper's literal
        // reading became the default: they pin that the choices are the only change.
        let earlier = |mut s: Scenario| {
            s.guidance.hidden_resolution = HiddenResolution::Planning;
            s.guidance.hidden_window = protocol::scenario::HiddenWindow::Periods;
            s.guidance.predicted_views = PredictedViews::EveryFrame;
            s.guidance.border = PlanBorder::Region;
            s
        };
        let paper = GuidanceParams::from_scenario(&earlier(scenario()));
        let literal = GuidanceParams::from_scenario(&scenario());
        let mut s = earlier(scenario());
        // The `setfleet` variant's settings.
        s.guidance.planner = Planner::Setfleet;
        s.timing.guidance_period_s = 1.0;
        s.guidance.lambda = 10.0;
        s.guidance.target_weight = 1.0;
        let setfleet = GuidanceParams::from_scenario(&s);
        let mut rng = Xorshift(0x9e37_79b9_7f4a_7c15);
        let mut fingerprints = Vec::new();
        let mut literal_fingerprints = Vec::new();
        for case in 0..6 {
            let fine = &paper.grids.fine;
            let mut undetected = CellSet::empty(fine);
            for _ in 0..5 {
                undetected.or_assign(&rng.disc(fine, 140.0, 10.0, 60.0));
            }
            let targets: Vec<CellSet> = (0..case % 3)
                .map(|_| rng.disc(fine, 140.0, 3.0, 12.0))
                .collect();
            let hidden = rng.disc(fine, 140.0, 5.0, 40.0);
            let obstacles: Vec<ObstacleCell> = (0..40 + 30 * case)
                .map(|_| rng.building(10.0, 60.0))
                .collect();
            let mut flown = |uav: u32| {
                let state = UavState {
                    position: Point3::new(
                        rng.uniform(-100.0, 100.0),
                        rng.uniform(-100.0, 100.0),
                        60.0,
                    ),
                    yaw: rng.uniform(-3.0, 3.0),
                };
                let (state, poses) = turning(state, rng.uniform(-1.0, 1.0));
                (state, PlannedView { uav, poses })
            };
            let others: Vec<PlannedView> = (0..case % 4).map(|u| flown(u).1).collect();
            let me = flown(7).0;
            let mut sets = vec![&undetected];
            sets.extend(targets.iter());
            let input = PlanningInput {
                uav: 7,
                state: UavState {
                    position: Point3::new(me.position.x, me.position.y, 50.0 + 5.0 * case as f64),
                    yaw: me.yaw,
                },
                sets: &sets,
                recently_hidden: &hidden,
                obstacles: &obstacles,
                others: &others,
            };
            fingerprints.push(fingerprint(&plan(&paper, &input)));
            fingerprints.push(fingerprint(&setfleet::plan(&setfleet, &input)));
            literal_fingerprints.push(fingerprint(&plan(&literal, &input)));
        }
        // Paper, setfleet, for each case.
        let recorded: [u64; 12] = [
            0x0e04_f031_d77b_ae59,
            0xd4ce_cd2e_8a90_0c71,
            0x24c4_c384_cf18_d850,
            0xc627_d2a4_05fb_0103,
            0xc695_76a1_33c5_855f,
            0xc3fb_a2f7_098f_2d0c,
            0x878d_2e04_628e_0aab,
            0x0b6a_403d_cb36_9ef1,
            0xb3a3_a5ac_2c01_ba91,
            0xb1ea_e9f9_a44f_ab05,
            0x72e9_7fc7_4d93_b48d,
            0x4ee4_5686_6ce9_29ac,
        ];
        assert_eq!(fingerprints, recorded, "{fingerprints:#x?}");
        // The paper's literal reading (the defaults), for each case.
        let recorded: [u64; 6] = [
            0x5f5d_52dd_dcf0_b195,
            0xf447_e6a4_cf18_dd69,
            0x9764_f986_a95d_d859,
            0x663a_7931_13e1_13a3,
            0x6ac9_81cc_2c01_b72b,
            0x4056_88f6_40fe_5ea8,
        ];
        assert_eq!(literal_fingerprints, recorded, "{literal_fingerprints:#x?}");
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
                obstacles: &situation.obstacles,
                others: &situation.others,
            };
            let fast = plan(&params, &input);
            let reference = plan_exhaustive(&params, &input);
            assert_eq!(fingerprint(&fast), fingerprint(&reference), "seed {seed}");
            assert_eq!(fast, reference, "seed {seed}");
        }
    }
}
