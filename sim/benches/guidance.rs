//! Guidance benchmarks on the default scenario: one decision of each planner (the paper's MPC
//! and the `setfleet` variant's beam search) on a run's sets and maps, for each UAV of a round
//! with the plans of the UAVs before it in the token, and the predicted view of one pose.
//!
//! `cargo bench -p sim --bench guidance`

use std::sync::OnceLock;

use divan::Bencher;
use protocol::camera::CameraPose;
use protocol::flight::UavState;
use protocol::scenario::{Planner, Scenario};
use protocol::wire::PlannedView;
use sets::raster::CellSet;
use sim::{Fleet, FleetOptions, Steering};
use uav_agent::estimator::Estimator;
use uav_agent::guidance::{self, GroundPredictor, GuidanceParams, ObstacleCell, PlanningInput};

/// Steps flown before measuring, so the sets and the maps are a run's.
const WARMUP_STEPS: u64 = 60;

/// What one UAV plans from, owned.
struct Inputs {
    state: UavState,
    sets: Vec<CellSet>,
    hidden: CellSet,
    obstacles: Vec<ObstacleCell>,
    /// The plans of the UAVs before it in the round.
    others: Vec<PlannedView>,
}

impl Inputs {
    fn of(estimator: &Estimator, others: Vec<PlannedView>) -> Self {
        let st = estimator.state();
        let pose = st.pose.expect("a pose after the warm-up");
        Self {
            state: UavState {
                position: pose.position,
                yaw: pose.yaw,
            },
            sets: st.target_sets().cloned().collect(),
            hidden: st.hidden_history.recently_hidden(),
            obstacles: ObstacleCell::known(&st.oem),
            others,
        }
    }

    fn decide(&self, params: &GuidanceParams) -> guidance::Decision {
        let sets: Vec<&CellSet> = self.sets.iter().collect();
        guidance::decide(
            params,
            &PlanningInput {
                uav: 0,
                state: self.state,
                sets: &sets,
                recently_hidden: &self.hidden,
                obstacles: &self.obstacles,
                others: &self.others,
            },
        )
    }
}

struct Fixture {
    paper: GuidanceParams,
    setfleet: GuidanceParams,
    /// Each UAV's inputs at the first guidance step after the warm-up, in token order.
    round: Vec<Inputs>,
}

fn fixture() -> &'static Fixture {
    static FIXTURE: OnceLock<Fixture> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let scenario = Scenario::default();
        let paper = GuidanceParams::from_scenario(&scenario);
        let mut variant = scenario.clone();
        // The `setfleet` variant's settings (`fleet --variant setfleet`).
        variant.guidance.planner = Planner::Setfleet;
        variant.timing.guidance_period_s = 1.0;
        variant.guidance.lambda = 10.0;
        variant.guidance.target_weight = 1.0;
        variant.guidance.spread_m = 60.0;
        let setfleet = GuidanceParams::from_scenario(&variant);
        // The fleet flies the paper's MPC in token order, as in a run.
        let options = FleetOptions {
            steering: Steering::Guided(Box::new(paper.clone())),
            ..FleetOptions::default()
        };
        let mut fleet = Fleet::new(&scenario, options).expect("default world");
        let decisions = loop {
            let sample = fleet.step().expect("step");
            if sample.step >= WARMUP_STEPS && !sample.decisions.is_empty() {
                break sample.decisions;
            }
        };
        // Each UAV's inputs of that round: its estimator's state, the plans of those before it.
        let views: Vec<PlannedView> = decisions.into_iter().map(|d| d.view).collect();
        let round: Vec<Inputs> = fleet
            .estimators()
            .iter()
            .enumerate()
            .map(|(i, e)| Inputs::of(e, views[..i].to_vec()))
            .collect();
        let obstacles: Vec<usize> = round.iter().map(|r| r.obstacles.len()).collect();
        eprintln!("obstacle cells known per UAV: {obstacles:?}");
        Fixture {
            paper,
            setfleet,
            round,
        }
    })
}

fn main() {
    fixture();
    divan::main();
}

/// One decision of the paper's MPC (25 sequences of 2 periods of 6 steps), by the UAV at
/// this place in the token (0: no plan ahead; 3: three).
#[divan::bench(args = [0, 1, 2, 3])]
fn paper(bencher: Bencher, place: usize) {
    let f = fixture();
    let inputs = &f.round[place.min(f.round.len() - 1)];
    bencher.bench(|| inputs.decide(&f.paper).cost.total);
}

/// One decision of the `setfleet` variant (a beam of 4 over 6 periods of 2 steps).
#[divan::bench(args = [0, 1, 2, 3])]
fn setfleet(bencher: Bencher, place: usize) {
    let f = fixture();
    let inputs = &f.round[place.min(f.round.len() - 1)];
    bencher.bench(|| inputs.decide(&f.setfleet).cost.total);
}

/// The predicted view of the UAV's current pose over the whole grid, and only on its sets.
#[divan::bench(args = ["whole grid", "sets only"])]
fn predicted_view(bencher: Bencher, ground: &str) {
    let f = fixture();
    let inputs = &f.round[0];
    let grids = &f.paper.grids;
    let grid = grids.coarse;
    let mut relevant = CellSet::empty(&grid);
    for s in &inputs.sets {
        relevant.or_assign(&grids.downsample(s));
    }
    if ground == "whole grid" {
        relevant = CellSet::full(&grid);
    }
    let pose = CameraPose {
        position: inputs.state.position,
        yaw: inputs.state.yaw,
    };
    let mut predictor = GroundPredictor::new(&grid);
    bencher.bench_local(|| {
        let mut seen = CellSet::empty(&grid);
        predictor.add_visible_ground_within(
            &mut seen,
            &grid,
            &f.paper.camera,
            &pose,
            &inputs.obstacles,
            &relevant,
        );
        seen.count()
    });
}
