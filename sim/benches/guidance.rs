//! Guidance benchmarks on the default scenario: one decision of each planner (the paper's MPC
//! and the `setfleet` variant's beam search) on a run's sets and maps, for each UAV of a round
//! with the plans of the UAVs before it in the token, and the predicted view of one pose.
//!
//! `cargo bench -p sim --bench guidance`

use std::sync::OnceLock;

use divan::Bencher;
use estimator::Estimator;
use protocol::camera::CameraPose;
use protocol::flight::UavState;
use protocol::scenario::Scenario;
use protocol::variant::Variant;
use protocol::wire::PlannedView;
use sets::raster::CellSet;
use sim::{Fleet, FleetOptions, Steering};
use uav_agent::guidance::{self, GroundPredictor, GuidanceParams, ObstacleCell, PlanningInput};

/// Steps flown before measuring, so the sets and the maps are a run's.
const WARMUP_STEPS: u64 = 60;

/// What one UAV plans from, owned.
struct Inputs {
    uav: u32,
    state: UavState,
    sets: Vec<CellSet>,
    hidden: CellSet,
    unseen: CellSet,
    obstacles: Vec<ObstacleCell>,
    /// The plans of the UAVs before it in the round.
    others: Vec<PlannedView>,
    /// The round's fleet.
    fleet: Vec<u32>,
}

impl Inputs {
    fn of(uav: u32, estimator: &Estimator, others: Vec<PlannedView>, fleet: Vec<u32>) -> Self {
        let st = estimator.state();
        let pose = st.pose.expect("a pose after the warm-up");
        Self {
            uav,
            state: UavState {
                position: pose.position,
                yaw: pose.yaw,
            },
            sets: st.target_sets().cloned().collect(),
            hidden: st.hidden_history.recently_hidden(),
            unseen: st.hidden_history.unseen().clone(),
            obstacles: ObstacleCell::known(&st.oem),
            others,
            fleet,
        }
    }

    fn decide(&self, params: &GuidanceParams) -> guidance::Decision {
        let sets: Vec<&CellSet> = self.sets.iter().collect();
        guidance::decide(
            params,
            &PlanningInput {
                uav: self.uav,
                state: self.state,
                sets: &sets,
                recently_hidden: &self.hidden,
                unseen: &self.unseen,
                obstacles: &self.obstacles,
                others: &self.others,
                fleet: &self.fleet,
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
        // The `setfleet` variant's settings (`fleet --variant setfleet`).
        let variant = Scenario::load(None, &Variant::Setfleet.with_user_overrides(&[]))
            .expect("the setfleet variant");
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
        let ids: Vec<u32> = (0..fleet.estimators().len() as u32).collect();
        let round: Vec<Inputs> = fleet
            .estimators()
            .iter()
            .zip(&ids)
            .map(|(e, &i)| Inputs::of(i, e, views[..i as usize].to_vec(), ids.clone()))
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
