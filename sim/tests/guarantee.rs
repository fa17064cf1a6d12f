//! The guarantee, checked against the real world and renderer in-process: after every step of
//! every agent (and after fusing the agents' estimates), every target is in `X̄`, every
//! identified target is in its `X_j`, and no proven-free cell (`P^g`, `S^o`) holds a target.

use estimator::measure::{self, FrameView};
use estimator::{EstimatorConfig, EstimatorState};
use protocol::frame::CvsFrame;
use protocol::scenario::{DepthRay, RayAssumption, Scenario};
use protocol::wire::TruthState;
use sets::grid::GroundGrid;
use sets::math::Point2;
use sim::{Fleet, FleetOptions};

const RUN_TAG: u64 = 0x5e7f_1ee7;

fn small_scenario(seed: u64) -> Scenario {
    let mut s = Scenario {
        seed,
        ..Scenario::default()
    };
    s.region.half_extent_m = 100.0;
    s.camera.rows = 120;
    s.camera.cols = 160;
    s.targets.count = 5;
    s.uavs.count = 3;
    s
}

/// Every check of the guarantee on one state; `context` names the step and agent.
fn check_state(
    grid: &GroundGrid,
    state: &EstimatorState,
    truth: &TruthState,
    context: &str,
) -> usize {
    let mut checks = 0;
    for t in truth.targets() {
        let p = Point2::new(t.ground[0], t.ground[1]);
        let Some(cell) = grid.cell_of(&p) else {
            continue;
        };
        assert!(
            state.undetected.contains(cell),
            "{context}: target {} at {p:?} outside X̄",
            t.id
        );
        assert!(
            !state.obstacle_neighbourhood.contains(cell),
            "{context}: target {} at {p:?} inside S^o",
            t.id
        );
        if let Some(x) = state.targets.get(&t.id) {
            assert!(
                x.contains(cell),
                "{context}: target {} at {p:?} outside X_j",
                t.id
            );
        }
        checks += 1;
    }
    checks
}

/// Checks that this frame's `P^g` and `S^o` hold no target.
fn check_frame(config: &EstimatorConfig, frame: &CvsFrame, truth: &TruthState, context: &str) {
    let view = FrameView::new(frame, config.depth_noise, config.depth_ray);
    let grid = &config.grid;
    let free = measure::free_ground(&view, grid);
    let so = measure::obstacle_neighbourhood(&view, grid, config.safety_distance_m, 1);
    for t in truth.targets() {
        let p = Point2::new(t.ground[0], t.ground[1]);
        if let Some(cell) = grid.cell_of(&p) {
            assert!(!free.contains(cell), "{context}: target {} in P^g", t.id);
            assert!(!so.contains(cell), "{context}: target {} in S^o", t.id);
            // Every identified target is in its own measurement set X^m_j.
            let (rows, cols) = (frame.header.rows, frame.header.cols);
            for b in frame
                .boxes()
                .iter()
                .filter(|b| b.id == t.id && b.is_valid(rows, cols))
            {
                let xm = measure::target_measurement(&view, grid, b, config.target_radius_m);
                if let Some(xm) = xm {
                    assert!(
                        xm.contains(cell),
                        "{context}: target {} outside X^m_j",
                        t.id
                    );
                }
            }
        }
    }
}

struct Outcome {
    checks: usize,
    identified: usize,
    explored_m2: f64,
}

/// Runs every UAV's estimator over `steps` frames with yaws held, checking the guarantee after
/// each step and, when `fuse`, after fusing every agent's estimate (through encoded messages)
/// into every other.
fn run(scenario: &Scenario, steps: u64, fuse: bool) -> Outcome {
    let options = FleetOptions {
        run_tag: RUN_TAG,
        oem_full_every: Some(10),
        ..FleetOptions::default()
    };
    let mut fleet = Fleet::new(scenario, options).expect("world");
    for i in 0..fleet.uav_count() {
        let yaw = fleet.world().uav_state(i).expect("uav").yaw;
        fleet.world_mut().set_yaw_ref(i, yaw);
    }
    let config = fleet.config().clone();
    let mut truth = Box::<TruthState>::default();
    let mut checks = 0;
    for k in 0..steps {
        fleet.world().truth(RUN_TAG, &mut truth);
        let mut sample = fleet.sample();
        fleet
            .sense(&mut sample, |s| {
                let context = format!("seed {} step {k} uav {}", scenario.seed, s.uav);
                assert!(
                    s.report.empty_intersections.is_empty(),
                    "{context}: empty X_j"
                );
                check_frame(&config, s.frame, &truth, &context);
                checks += check_state(&config.grid, s.estimator.state(), &truth, &context);
            })
            .expect("frame accepted");
        if fuse {
            fleet
                .share(&mut sample, |f| {
                    assert!(f.report.is_none_or(|r| r.empty_intersections.is_empty()));
                    assert!(f.applied.is_none_or(|r| r.empty_intersections.is_empty()));
                })
                .expect("estimates exchanged");
            for (i, est) in fleet.estimators().iter().enumerate() {
                let context = format!("seed {} step {k} uav {i} fused", scenario.seed);
                checks += check_state(&config.grid, est.state(), &truth, &context);
            }
        }
        fleet.advance();
    }
    let identified = fleet
        .estimators()
        .iter()
        .map(|e| e.state().targets.len())
        .max()
        .unwrap_or(0);
    let explored_m2 = fleet
        .estimators()
        .iter()
        .map(|e| e.state().explored.area(&config.grid))
        .fold(0.0, f64::max);
    Outcome {
        checks,
        identified,
        explored_m2,
    }
}

#[test]
fn targets_stay_in_their_sets_over_seeds() {
    for seed in 1..=3 {
        let out = run(&small_scenario(seed), 200, false);
        assert!(out.checks > 0);
        assert!(out.explored_m2 > 0.0, "seed {seed}: nothing explored");
        eprintln!(
            "seed {seed}: {} checks, {} identified",
            out.checks, out.identified
        );
    }
}

#[test]
fn targets_stay_in_their_sets_at_max_noise_and_doubt() {
    let mut s = small_scenario(7);
    s.camera.depth_noise = [-0.05, 0.05];
    s.camera.unknown_fraction = 0.2;
    let out = run(&s, 200, false);
    assert!(out.checks > 0);
}

#[test]
fn fused_estimates_keep_the_guarantee() {
    for seed in [4, 5] {
        let out = run(&small_scenario(seed), 200, true);
        assert!(out.checks > 0);
        eprintln!("seed {seed} fused: {} identified", out.identified);
    }
}

#[test]
fn exchanged_measurements_keep_the_guarantee() {
    for seed in [4, 6] {
        let mut s = small_scenario(seed);
        s.comms.exchange = protocol::scenario::Exchange::Measurements;
        let out = run(&s, 200, true);
        assert!(out.checks > 0 && out.identified > 0);
        eprintln!("seed {seed} measurements: {} identified", out.identified);
    }
}

#[test]
fn default_scenario_keeps_the_guarantee() {
    let out = run(&Scenario::default(), 40, true);
    assert!(out.checks > 0);
}

/// The paper's sensor model (eq. 5): the world measures depth along a random ray of each
/// pixel and lets the cars come as close to the walls as the paper allows (`r_s`); the
/// estimator's default rule keeps the guarantee on every frame and state, fused or not.
fn random_ray_scenario(seed: u64) -> Scenario {
    let mut s = small_scenario(seed);
    s.camera.depth_ray = DepthRay::Random;
    s.targets.building_clearance_m = s.targets.safety_distance_m;
    s.targets.count = 10;
    s.region.building_fraction = 0.12;
    s
}

#[test]
fn random_depth_rays_keep_the_guarantee_under_the_default_rule() {
    for seed in [2, 9] {
        let s = random_ray_scenario(seed);
        assert_eq!(s.estimator.depth_ray, RayAssumption::Any);
        let out = run(&s, 200, seed == 9);
        assert!(out.checks > 0 && out.identified > 0);
        eprintln!("seed {seed} random rays: {} checks", out.checks);
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(12))]

    /// Single frames of random-ray worlds, from random seeds and random UAV headings: no car
    /// in `P^g` or `S^o`, every identified car in its `X^m_j`.
    #[test]
    fn random_ray_frames_hold_no_car_in_proven_free_ground(
        seed in 1u64..10_000,
        yaws in proptest::collection::vec(-3.2f64..3.2, 3),
        steps in 0u64..40,
    ) {
        let s = random_ray_scenario(seed);
        let mut fleet = Fleet::new(&s, FleetOptions { run_tag: RUN_TAG, ..FleetOptions::default() })
            .expect("world");
        for _ in 0..steps {
            fleet.advance();
        }
        for (i, &yaw) in yaws.iter().enumerate() {
            let mut state = fleet.world().uav_state(i).expect("uav");
            state.yaw = yaw;
            fleet.world_mut().set_uav_state(i, state);
        }
        let config = fleet.config().clone();
        let mut truth = Box::<TruthState>::default();
        fleet.world().truth(RUN_TAG, &mut truth);
        let mut frame = CvsFrame::new_boxed();
        for i in 0..fleet.uav_count() {
            fleet.world().render(i, RUN_TAG, &mut frame);
            check_frame(&config, &frame, &truth, &format!("seed {seed} uav {i}"));
        }
    }
}
