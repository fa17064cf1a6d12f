//! The cars keep their safety distances, stay on the roads inside the RoI, never exceed
//! `v_max`, for whole runs; and the world is deterministic, bit for bit.

use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use protocol::wire::TruthState;
use rayon::ThreadPoolBuilder;
use sets::math::{Point2, Real};
use world_server::{World, WorldBuildError};

/// Runs `steps` steps, steering the UAVs with a fixed pattern, and checks every car at every
/// step. Returns the total distance driven and the closest a car came to a building.
fn run_and_check(s: &Scenario, steps: u64) -> (Real, Real) {
    let mut world = World::new(s).expect("scenario builds");
    let city = world.scene().clone();
    let t = &s.targets;
    let [length, _, _] = t.size_m;
    let separation = t.safety_distance_m.max(length);
    let dt = s.timing.cvs_period_s;
    let h = s.region.half_extent_m;
    let (mut driven, mut closest) = (0.0, Real::INFINITY);
    let mut prev: Vec<Point2> = world.targets().iter().map(|c| c.position).collect();
    for k in 0..steps {
        for i in 0..world.uav_count() {
            world.set_yaw_ref(i, (k as Real * 0.05 + i as Real).sin() * 3.0);
        }
        world.advance();
        let cars = world.targets();
        for (car, p0) in cars.iter().zip(&prev) {
            let p = car.position;
            let moved = (p - p0).norm();
            driven += moved;
            assert!(
                moved <= t.max_speed_mps * dt + 1e-9,
                "car {} moved {moved}",
                car.id
            );
            assert!(car.speed_mps <= t.max_speed_mps + 1e-12);
            assert!(city.is_on_road(&p), "car {} off road at {p}", car.id);
            // The whole body inside the RoI.
            let reach = length.hypot(t.size_m[1]) / 2.0;
            assert!(
                p.x.abs() + reach < h && p.y.abs() + reach < h,
                "car {} at {p}",
                car.id
            );
            // The paper's assumption (more than r_s), and the scenario's clearance.
            for b in &city.buildings {
                let d = b.footprint_distance(&p);
                closest = closest.min(d);
                assert!(
                    d >= t.building_clearance_m - 1e-9,
                    "car {} {d} m from a wall",
                    car.id
                );
                assert!(d >= t.safety_distance_m - 1e-9);
            }
        }
        for (i, a) in cars.iter().enumerate() {
            for b in &cars[i + 1..] {
                let d = (a.position - b.position).norm();
                assert!(d > separation, "cars {} and {} at {d} m", a.id, b.id);
            }
        }
        for u in world.uavs() {
            let p = u.state.position;
            assert!(p.x.abs() < h && p.y.abs() < h);
        }
        prev = cars.iter().map(|c| c.position).collect();
    }
    (driven, closest)
}

#[test]
fn cars_keep_their_distances_for_a_whole_run() {
    for seed in 1..=3 {
        let s = Scenario {
            seed,
            ..Scenario::default()
        };
        let steps = s.steps();
        assert_eq!(steps, 600);
        let (driven, _) = run_and_check(&s, steps);
        // 8 cars at no less than 0.4 m/s would drive 960 m unhindered.
        assert!(driven > 500.0, "seed {seed}: {driven}");
    }
}

/// The shipped Helsinki scenario (`scenarios/cities/helsinki`): its cars keep every distance
/// on a road network and around buildings that no generator made.
#[test]
fn cars_keep_their_distances_in_an_imported_city() {
    let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios/cities/helsinki/scenario.toml");
    for seed in 1..=3 {
        let mut s = Scenario::load(Some(&file), &[]).expect("the shipped scenario loads");
        s.seed = seed;
        assert!(
            !World::new(&s).unwrap().scene().buildings[0]
                .parts
                .is_empty()
        );
        let (driven, closest) = run_and_check(&s, s.steps());
        assert!(driven > 500.0, "seed {seed}: {driven}");
        assert!(closest.is_finite(), "seed {seed}");
    }
}

/// With `targets.building_clearance_m = r_s`, the cars come as close to the walls as the paper
/// allows, and some do.
#[test]
fn cars_may_come_as_close_to_walls_as_the_paper_allows() {
    let mut s = Scenario {
        seed: 4,
        ..Scenario::default()
    };
    s.targets.building_clearance_m = s.targets.safety_distance_m;
    let (_, closest) = run_and_check(&s, 600);
    assert!(closest < s.targets.safety_distance_m + 0.5, "{closest}");
}

/// Each car's speed at every step of a 300 s run (`targets.speed_draw`, `stops_per_min`).
fn speeds(s: &Scenario) -> Vec<Vec<Real>> {
    let mut world = World::new(s).expect("scenario builds");
    let mut out = vec![Vec::new(); world.targets().len()];
    for _ in 0..s.steps() {
        world.advance();
        for (v, car) in out.iter_mut().zip(world.targets()) {
            v.push(car.speed_mps);
        }
    }
    out
}

/// The speed models keep every bound (the paper's `v_max`, the distances), and do what they
/// say: a speed drawn per step varies from step to step where a speed per car does not, and
/// stops leave cars standing for about the share of time they ask for.
#[test]
fn every_speed_model_keeps_the_bounds_and_does_what_it_says() {
    use protocol::scenario::SpeedDraw;
    let base = Scenario {
        seed: 6,
        ..Scenario::default()
    };
    let mut per_step = base.clone();
    per_step.targets.speed_draw = SpeedDraw::PerStep;
    let mut stops = base.clone();
    stops.targets.stops_per_min = 2.0;
    stops.targets.stop_s = [10.0, 10.0];
    let mut both = per_step.clone();
    both.targets.stops_per_min = 1.0;
    both.targets.building_clearance_m = both.targets.safety_distance_m;
    for s in [&per_step, &stops, &both] {
        let (driven, _) = run_and_check(s, s.steps());
        assert!(driven > 300.0, "{:?}: {driven}", s.targets);
    }
    // Distinct speeds of a car's unhindered moves (speed > 0), counted per car, summed.
    let distinct = |v: &[Vec<Real>]| -> usize {
        v.iter()
            .map(|car| {
                let mut moving: Vec<u64> = car
                    .iter()
                    .filter(|&&x| x > 0.0)
                    .map(|x| x.to_bits())
                    .collect();
                moving.sort_unstable();
                moving.dedup();
                moving.len()
            })
            .sum()
    };
    let standing = |v: &[Vec<Real>]| -> Real {
        let all: Vec<Real> = v.iter().flatten().copied().collect();
        all.iter().filter(|&&x| x == 0.0).count() as Real / all.len() as Real
    };
    let (b, p, st) = (speeds(&base), speeds(&per_step), speeds(&stops));
    // Per car: the cruise speed, and shortened moves (0.75, 0.5, 0.25 of it) near other cars.
    assert!(distinct(&b) <= 4 * b.len(), "{}", distinct(&b));
    assert!(distinct(&p) > 100 * p.len(), "{}", distinct(&p));
    // 2 stops of 10 s a minute: about a quarter of the time standing, on top of blockages.
    let (sb, ss) = (standing(&b), standing(&st));
    assert!(ss > sb + 0.15, "standing {sb} without stops, {ss} with");
    assert!(ss < sb + 0.40, "standing {sb} without stops, {ss} with");
}

#[test]
fn crowded_small_city_keeps_distances_and_moves() {
    let mut s = Scenario {
        seed: 5,
        ..Scenario::default()
    };
    s.region.half_extent_m = 100.0;
    s.region.building_fraction = 0.15;
    s.targets.count = 40;
    s.targets.safety_distance_m = 5.0;
    let (driven, _) = run_and_check(&s, 600);
    assert!(driven > 1000.0, "{driven}");
}

#[test]
fn too_many_cars_is_a_placement_error() {
    let mut s = Scenario::default();
    // A ring road alone, about 8 lanes of 27 m: room for far fewer than 64 cars.
    s.region.half_extent_m = 20.0;
    s.region.building_fraction = 0.0;
    s.targets.count = 64;
    assert!(matches!(World::new(&s), Err(WorldBuildError::Placement(_))));
}

#[test]
fn same_seed_same_trajectories_and_frames() {
    let mut s = Scenario {
        seed: 42,
        ..Scenario::default()
    };
    s.camera.rows = 36;
    s.camera.cols = 48;
    s.camera.unknown_fraction = 0.02;
    let run = |threads: usize| {
        let pool = ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut world = World::new(&s).unwrap();
            let mut frame = CvsFrame::new_boxed();
            let mut truths = Vec::new();
            let mut sums = Vec::new();
            for k in 0..600u64 {
                for i in 0..world.uav_count() {
                    world.set_yaw_ref(i, (k as Real * 0.07 * (i + 1) as Real).cos() * 2.5);
                }
                world.advance();
                let mut t = TruthState::default();
                world.truth(3, &mut t);
                truths.push(t);
                if k % 25 == 0 {
                    for i in 0..world.uav_count() {
                        world.render(i, 3, &mut frame);
                        sums.push((frame.header.checksum, frame.boxes().to_vec()));
                    }
                }
            }
            (truths, sums)
        })
    };
    let (t1, f1) = run(1);
    let (t2, f2) = run(2);
    assert_eq!(t1.len(), 600);
    assert!(t1 == t2, "truth differs");
    assert_eq!(f1, f2);
    // A different seed is a different world.
    let mut other = s.clone();
    other.seed = 43;
    let mut w = World::new(&other).unwrap();
    w.advance();
    let mut t = TruthState::default();
    w.truth(3, &mut t);
    assert!(t != t1[0]);
}

#[test]
fn truth_reports_every_car_and_uav() {
    let s = Scenario::default();
    let world = World::new(&s).unwrap();
    let mut t = TruthState::default();
    world.truth(11, &mut t);
    assert_eq!(t.run_tag, 11);
    assert_eq!(t.targets().len(), 8);
    assert_eq!(t.uavs().len(), 4);
    for (u, w) in t.uavs().iter().zip(world.uavs()) {
        assert_eq!(u.agent_live, 1);
        assert_eq!(u.position[2], w.state.position.z);
    }
    for (c, w) in t.targets().iter().zip(world.targets()) {
        assert_eq!(c.ground, [w.position.x, w.position.y]);
    }
}
