//! Cars driven by SUMO and by trace files (`city.traffic`): SUMO's drive over the shipped
//! Helsinki square keeps every check and is the same for the same seed; a trace that breaks a
//! check is refused, naming the car and the time.
//!
//! SUMO must be installed (`.ci/run` installs it): these tests fail, saying how to install it,
//! where it is missing.

use std::path::{Path, PathBuf};

use protocol::scenario::{CityTraffic, Scenario};
use sets::math::{Point2, Real};
use world_server::traffic::trace::{HEADER, Trace};
use world_server::{World, WorldBuildError};

fn helsinki(overrides: &[&str]) -> Scenario {
    let file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/cities/helsinki/scenario.toml");
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    Scenario::load(Some(&file), &overrides).expect("the shipped scenario loads")
}

fn sumo_world(seed: u64) -> World {
    let mut s = helsinki(&["city.traffic=\"sumo\"", "duration_s=120"]);
    s.seed = seed;
    World::new(&s).unwrap_or_else(|e| panic!("seed {seed}: {e}"))
}

/// Every car's every step over the run: at most `v_max T`, the clearance from every building,
/// inside the region; returns how far the cars drove.
fn drive_and_check(mut world: World) -> Vec<Real> {
    let s = world.scenario().clone();
    let t = &s.targets;
    let city = world.scene().clone();
    let max_step = t.max_speed_mps * s.timing.cvs_period_s;
    let mut prev: Vec<Point2> = world.targets().iter().map(|c| c.position).collect();
    let mut driven = vec![0.0; prev.len()];
    for _ in 0..s.steps() {
        world.advance();
        for car in world.targets() {
            let i = car.id as usize;
            let moved = (car.position - prev[i]).norm();
            assert!(moved <= max_step, "car {i} moved {moved} m");
            driven[i] += moved;
            prev[i] = car.position;
            let h = s.region.half_extent_m;
            assert!(car.position.x.abs() < h && car.position.y.abs() < h);
            for b in &city.buildings {
                assert!(b.footprint_distance(&car.position) >= t.building_clearance_m);
            }
        }
    }
    driven
}

#[test]
fn sumo_drives_the_city_within_every_check_and_the_same_for_the_same_seed() {
    for seed in 1..=3 {
        let world = sumo_world(seed);
        assert!(matches!(world.scenario().city.traffic, CityTraffic::Sumo));
        assert_eq!(world.targets().len(), 8);
        let again = sumo_world(seed);
        assert_eq!(world.targets(), again.targets(), "seed {seed}");
        let driven = drive_and_check(world);
        // SUMO's cars drive: each car at least a quarter of what v_max would take it.
        for (car, d) in driven.iter().enumerate() {
            assert!(*d > 60.0, "seed {seed}: car {car} drove only {d} m");
        }
    }
    assert_ne!(sumo_world(1).targets(), sumo_world(2).targets());
}

#[test]
fn sumo_refuses_more_cars_than_the_roads_hold() {
    let mut s = helsinki(&["city.traffic=\"sumo\"", "duration_s=20", "targets.count=64"]);
    s.seed = 1;
    let e = World::new(&s).expect_err("64 cars do not fit");
    assert!(
        matches!(e, WorldBuildError::Sumo(_)) && e.to_string().contains("targets.count"),
        "{e}"
    );
}

/// A trace of `sumo_world(1)`'s first 60 s, written to a file, with `edit` applied.
fn trace_file(name: &str, edit: impl Fn(&mut Vec<String>)) -> PathBuf {
    let mut world = sumo_world(1);
    let period = world.scenario().timing.cvs_period_s;
    let mut points = Vec::new();
    for _ in 0..=120 {
        let row = (world.targets().iter())
            .map(|c| (c.position.x, c.position.y, c.heading))
            .collect();
        points.push(row);
        world.advance();
    }
    let csv = Trace::from_points(period, &points).to_csv();
    let mut lines: Vec<String> = csv.lines().map(str::to_owned).collect();
    edit(&mut lines);
    let dir = std::env::temp_dir().join(format!("setfleet-trace-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let file = dir.join(name);
    std::fs::write(&file, lines.join("\n")).expect("the trace file");
    file
}

fn trace_world(file: &Path) -> Result<World, WorldBuildError> {
    let trace = format!("city.trace={:?}", file.display().to_string());
    let mut s = helsinki(&["city.traffic=\"trace\"", &trace, "duration_s=60"]);
    s.seed = 1;
    World::new(&s)
}

#[test]
fn a_trace_file_drives_the_cars_and_one_that_breaks_a_check_is_refused() {
    // As written: the same cars as SUMO's.
    let file = trace_file("as-is.csv", |_| {});
    let world = trace_world(&file).expect("SUMO's own trace is accepted");
    assert_eq!(world.targets(), sumo_world(1).targets());
    // Car 3 jumps 5 m at 10 s.
    let jump = trace_file("jump.csv", |lines| {
        let row = lines.iter().position(|l| l.starts_with("10,3,")).unwrap();
        let f: Vec<String> = lines[row].split(',').map(str::to_owned).collect();
        let x: Real = f[2].parse().unwrap();
        lines[row] = format!("10,3,{},{},{}", x + 5.0, f[3], f[4]);
    });
    let e = trace_world(&jump)
        .expect_err("a jump is refused")
        .to_string();
    assert!(
        e.contains("car 3 moves") && e.contains("from 9.5 s to 10 s"),
        "{e}"
    );
    // Car 0 parked inside a building at 0 s.
    let inside = trace_file("inside.csv", |lines| {
        let world = sumo_world(1);
        let b = &world.scene().buildings[0];
        let c = b.centre();
        lines[1] = format!("0,0,{},{},0", c.x, c.y);
    });
    let e = trace_world(&inside)
        .expect_err("a car in a wall is refused")
        .to_string();
    assert!(
        e.contains("car 0 at 0 s") && e.contains("building_clearance_m"),
        "{e}"
    );
    // Too short, and not a trace.
    let short = trace_file("short.csv", |lines| lines.truncate(1 + 8 * 60));
    let e = trace_world(&short).expect_err("short").to_string();
    assert!(e.contains("before the run's end"), "{e}");
    let junk = trace_file("junk.csv", |lines| lines[0] = "t,car,x,y".into());
    let e = trace_world(&junk).expect_err("junk").to_string();
    assert!(e.contains(HEADER), "{e}");
    let _ = std::fs::remove_dir_all(file.parent().unwrap());
}
