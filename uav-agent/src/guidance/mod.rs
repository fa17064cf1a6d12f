//! Guidance: one decision per guidance period, by the planner `guidance.planner` names.
//!
//! - `paper` (the default): the MPC of docs/design.md §4 (the paper's Sections VI-VII) as the
//!   paper writes it, [`paper::plan`]. The `paper` variant runs it untouched.
//! - `setfleet`: the project's own planner, [`setfleet::plan`]: a beam search over longer
//!   sequences that values the future growth of unobserved sets (see its docs).
//! - `external`: a planner of another process answers ([`external`], docs/python.md); the
//!   agent's loop asks it and falls back to the paper's MPC (or, for the UAVs of
//!   `guidance.external_uavs`, to the variant's planner) when no valid answer comes in time.
//!
//! [`decide`] picks between them. This module holds what the two share: the settings of a run
//! ([`GuidanceParams`]), what a decision looks at ([`PlanningInput`]) and what it gives
//! ([`Decision`] and its [`Cost`]), the UAV's predicted flight, and the parts both planners
//! predict with: the planning grid ([`coarse`]), the predicted views ([`view`]) and the token
//! that orders the decisions of a round ([`ring`]).

pub mod coarse;
pub mod external;
pub mod growth;
pub mod paper;
pub mod ring;
pub mod setfleet;
pub mod sweep;
pub mod view;
pub mod viewpoint;
pub mod weights;

use protocol::camera::{CameraModel, CameraPose};
use protocol::flight::{self, UavState};
use protocol::scenario::{
    DistanceFrom, HiddenResolution, HiddenSets, PlanBorder, Planner, PredictedViews, Scenario,
    SetResolution, SetfleetConfig,
};
use protocol::wire::PlannedView;
use sets::grid::Rect;
use sets::math::{Point2, Point3};
use sets::raster::CellSet;

pub use coarse::{CellWeights, CoarseGrid};
pub use ring::{TokenRing, Turn};
pub use view::{GroundPredictor, ObstacleCell};
use weights::WeightFactors;

/// Everything about guidance (both planners) that does not change during a run.
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
    /// Weight of `Φ_d` (the `setfleet` planner's scaled to the scenario with
    /// `guidance.adapt_weights`, [`weights`]).
    pub lambda: f64,
    /// Weight of `Φ_h`.
    pub kappa: f64,
    /// Whether the occupancy map's buildings hide ground in predictions.
    pub use_map: bool,
    /// How `Φ_h` measures the sets inside hidden ground (`guidance.hidden_resolution`).
    pub hidden_resolution: HiddenResolution,
    /// Which predicted poses' views clear the predicted sets (`guidance.predicted_views`).
    pub predicted_views: PredictedViews,
    /// The grid the paper's MPC predicts its sets on (`guidance.set_resolution`).
    pub set_resolution: SetResolution,
    /// The point the paper's MPC measures `Φ_d` from (`guidance.distance_from`).
    pub distance_from: DistanceFrom,
    /// Which sets the paper's MPC counts inside recently hidden ground
    /// (`guidance.hidden_sets`).
    pub hidden_sets: HiddenSets,
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
    /// The radio's range (`comms.range_m`), m: the `setfleet` planner counts the plans of the
    /// UAVs within it only.
    pub comms_range_m: f64,
    /// Which planner [`decide`] runs (never `External`: an asking agent's fallback).
    pub planner: Planner,
    /// The `setfleet` planner's settings as the scenario gives them (unused by the paper's
    /// MPC); [`GuidanceParams::spread_m`] and [`GuidanceParams::track_revisit_s`] scale them.
    pub setfleet: SetfleetConfig,
    /// What the `setfleet` weights given are multiplied by ([`weights`]).
    pub weight_factors: WeightFactors,
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
        let weight_factors = WeightFactors::of(s);
        Self {
            grids: CoarseGrid::new(s.grid()),
            camera: s.camera_model(),
            region: Rect {
                min: Point2::new(-h, -h),
                max: Point2::new(h, h),
            },
            horizon: s.guidance.horizon,
            increments: s.guidance.yaw_increments_rad.clone(),
            lambda: weight_factors.lambda(s.guidance.lambda),
            kappa: s.guidance.kappa,
            use_map: s.guidance.use_map,
            hidden_resolution: s.guidance.hidden_resolution,
            predicted_views: s.guidance.predicted_views,
            set_resolution: s.guidance.set_resolution,
            distance_from: s.guidance.distance_from,
            hidden_sets: s.guidance.hidden_sets,
            steps_per_period: s.steps_per_guidance() as u32,
            dt: s.timing.cvs_period_s,
            speed: s.uavs.speed_mps,
            max_yaw_rate: s.uavs.max_yaw_rate_rps,
            target_max_speed: s.targets.max_speed_mps,
            comms_range_m: s.comms.range_m,
            // An external planner's fallback is the paper's MPC.
            planner: match s.guidance.planner {
                Planner::External => Planner::Paper,
                p => p,
            },
            setfleet: s.guidance.setfleet,
            weight_factors,
            parallel: true,
        }
    }

    /// `spread_m` as the `setfleet` planner uses it (scaled to the scenario with
    /// `guidance.adapt_weights`).
    pub fn spread_m(&self) -> f64 {
        self.weight_factors.spread_m(self.setfleet.spread_m)
    }

    /// `track_revisit_s` as the `setfleet` planner uses it (scaled to the scenario with
    /// `guidance.adapt_weights`).
    pub fn track_revisit_s(&self) -> f64 {
        self.weight_factors
            .track_revisit_s(self.setfleet.track_revisit_s)
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
    /// `H̄`: ground hidden earlier and not proven free since, by the fleet as the agent knows
    /// it, on the estimator's grid.
    pub unseen: &'a CellSet,
    /// Known buildings (ignored unless `use_map`).
    pub obstacles: &'a [ObstacleCell],
    /// Plans of the UAVs that decided before this one in the round, as the ring gives them
    /// ([`Turn::Decide`]; under `comms.liveness = "radio"`, those carried by the tokens the
    /// agent read from the UAVs before it that it heard).
    pub others: &'a [PlannedView],
    /// The round's fleet, which the `setfleet` sweep's lanes are shared among
    /// ([`TokenRing::fleet`]).
    pub fleet: &'a [u32],
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
        Planner::Paper | Planner::External => paper::plan(params, input),
        Planner::Setfleet => setfleet::plan(params, input),
    }
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

/// How far outside the region a position is, metres (0 inside).
fn stray(region: &Rect, p: &Point3) -> f64 {
    let dx = (region.min.x - p.x).max(p.x - region.max.x).max(0.0);
    let dy = (region.min.y - p.y).max(p.y - region.max.y).max(0.0);
    dx.max(dy)
}

#[cfg(test)]
mod tests {
    use super::paper::plan as paper_plan;
    use super::*;
    use protocol::flight;
    use sets::grid::GroundGrid;
    use sets::raster::Coverage;

    /// The default scenario over a 300 m square.
    pub(super) fn scenario() -> Scenario {
        let mut s = Scenario::default();
        s.region.half_extent_m = 150.0;
        s
    }

    /// The `setfleet` variant's weights are its own on the default scenario and scaled on
    /// another; the paper's planner ignores `guidance.adapt_weights`.
    #[test]
    fn the_setfleet_variant_scales_its_weights_to_the_scenario_only() {
        use protocol::variant::Variant;
        let params = |variant: Variant, user: &[&str]| {
            let user: Vec<String> = user.iter().map(|s| (*s).to_owned()).collect();
            let s = Scenario::load(None, &variant.with_user_overrides(&user)).unwrap();
            GuidanceParams::from_scenario(&s)
        };
        let default = params(Variant::Setfleet, &[]);
        assert_eq!(default.lambda, 10.0);
        assert_eq!(default.spread_m(), 60.0);
        assert_eq!(default.track_revisit_s(), 10.0);
        let faster = params(Variant::Setfleet, &["targets.max_speed_mps=4"]);
        assert_eq!(faster.track_revisit_s(), 5.0);
        let steep = params(Variant::Setfleet, &["camera.tilt_rad=1.0"]);
        assert!(steep.lambda < 10.0 && steep.spread_m() < 60.0);
        let paper = |user: &[&str]| params(Variant::Paper, user).lambda;
        let adapt = ["camera.tilt_rad=1.0", "guidance.adapt_weights=true"];
        assert_eq!(paper(&adapt), paper(&adapt[..1]));
    }

    /// A fixed xorshift stream, for test situations that stay the same on every machine.
    pub(super) struct Xorshift(pub(super) u64);

    impl Xorshift {
        /// Uniform in [lo, hi).
        pub(super) fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
            let s = &mut self.0;
            *s ^= *s << 13;
            *s ^= *s >> 7;
            *s ^= *s << 17;
            lo + (hi - lo) * (*s >> 11) as f64 / (1u64 << 53) as f64
        }

        /// A disc of `grid` centred in the square of half side `half` (metres), of radius in
        /// [lo, hi).
        pub(super) fn disc(&mut self, grid: &GroundGrid, half: f64, lo: f64, hi: f64) -> CellSet {
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
        pub(super) fn building(&mut self, lo: f64, hi: f64) -> ObstacleCell {
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
    pub(super) fn turning(mut state: UavState, turn: f64) -> (UavState, Vec<CameraPose>) {
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

    /// A fingerprint of everything a decision holds (FNV-1a over the bits of its numbers).
    pub(super) fn fingerprint(d: &Decision) -> u64 {
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
            s.guidance.set_resolution = SetResolution::Planning;
            s.guidance.distance_from = DistanceFrom::ViewCentre;
            s.guidance.hidden_sets = HiddenSets::Current;
            s
        };
        // The defaults before issue 42's departures became keys: the same decisions as
        // before (the previous defaults' fingerprints), so that those keys are the only change.
        let before_42 = |mut s: Scenario| {
            s.guidance.border = PlanBorder::Geofence;
            s.guidance.set_resolution = SetResolution::Planning;
            s.guidance.distance_from = DistanceFrom::ViewCentre;
            s.guidance.hidden_sets = HiddenSets::Current;
            s
        };
        let paper = GuidanceParams::from_scenario(&earlier(scenario()));
        let previous = GuidanceParams::from_scenario(&before_42(scenario()));
        let literal = GuidanceParams::from_scenario(&scenario());
        let mut s = earlier(scenario());
        // The `setfleet` variant's settings.
        s.guidance.planner = Planner::Setfleet;
        s.timing.guidance_period_s = 1.0;
        s.guidance.lambda = 10.0;
        s.guidance.setfleet.target_weight = 1.0;
        let setfleet = GuidanceParams::from_scenario(&s);
        let mut rng = Xorshift(0x9e37_79b9_7f4a_7c15);
        let mut fingerprints = Vec::new();
        let mut previous_fingerprints = Vec::new();
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
                unseen: &hidden,
                obstacles: &obstacles,
                others: &others,
                fleet: &[],
            };
            fingerprints.push(fingerprint(&paper_plan(&paper, &input)));
            fingerprints.push(fingerprint(&setfleet::plan(&setfleet, &input)));
            previous_fingerprints.push(fingerprint(&paper_plan(&previous, &input)));
            literal_fingerprints.push(fingerprint(&paper_plan(&literal, &input)));
        }
        // Paper, setfleet, for each case.
        let recorded: [u64; 12] = [
            0x0e04_f031_d77b_ae59,
            0x3026_0942_ef9b_d0e3,
            0x24c4_c384_cf18_d850,
            0xc841_93de_8796_0afb,
            0xc695_76a1_33c5_855f,
            0xe915_4a4a_bac0_f2e9,
            0x878d_2e04_628e_0aab,
            0x98b6_d2e5_cfce_f79c,
            0xb3a3_a5ac_2c01_ba91,
            0x158d_d6de_cab6_0dda,
            0x72e9_7fc7_4d93_b48d,
            0xe7ee_a741_f6fc_dff3,
        ];
        assert_eq!(fingerprints, recorded, "{fingerprints:#x?}");
        // The defaults before issue 42 (plans in the geofence, sets on the planning grid, `Φ_d`
        // from the view centre, `Φ_h` of today's sets), for each case.
        let recorded: [u64; 6] = [
            0x5f5d_52dd_dcf0_b195,
            0xf447_e6a4_cf18_dd69,
            0x9764_f986_a95d_d859,
            0x663a_7931_13e1_13a3,
            0x6ac9_81cc_2c01_b72b,
            0x4056_88f6_40fe_5ea8,
        ];
        assert_eq!(
            previous_fingerprints, recorded,
            "{previous_fingerprints:#x?}"
        );
        // The paper's literal reading (the defaults), for each case.
        let recorded: [u64; 6] = [
            0x2698_ee0e_f751_56d0,
            0xd323_11b1_e3a9_0c58,
            0x8bf7_7d95_9af1_1a2e,
            0xb9d2_5da7_ef7e_30a6,
            0xd4ff_80bf_6583_952a,
            0x9f90_eae6_68a3_3598,
        ];
        assert_eq!(literal_fingerprints, recorded, "{literal_fingerprints:#x?}");
    }
}
