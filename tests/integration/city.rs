//! `fleet city` imports the shipped extract into the shipped scenario, byte for byte; the
//! imported city flies with every target in its sets, its cars driven by the world's model or
//! by SUMO; and bad input (a file, an option, a scene that does not fit the scenario, a trace
//! that breaks the estimator's assumptions, SUMO missing, more cars than the roads hold apart)
//! exits with code 2 and a message that says what is wrong.

use std::path::{Path, PathBuf};
use std::process::Command;

use city::scene::CityScene;
use serde_json::Value;
use tests::{ChildGuard, EXIT_TIMEOUT, TestRun, binary, fleet_run, run_to_end};

fn extract() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/cities/helsinki.osm.pbf")
}

/// The shipped scenario `scenarios/cities/helsinki`.
fn shipped(file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios/cities/helsinki")
        .join(file)
}

fn summary(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

fn fleet_city(t: &TestRun, osm: &std::path::Path, extra: &[&str]) -> std::process::Output {
    run_to_end(
        Command::new(binary("fleet"))
            .arg("city")
            .arg("--osm")
            .arg(osm)
            .arg("--out")
            .arg(t.dir.join("out"))
            .args(extra),
    )
}

#[test]
fn the_shipped_extract_imports_into_a_scene_that_reads_back() {
    let t = TestRun::new("city");
    let out = fleet_city(&t, &extract(), &["--center", "60.1716,24.9443"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("buildings: 78"), "{stdout}");
    assert!(
        stdout.contains("cut") && stdout.contains("tunnels"),
        "{stdout}"
    );
    assert!(
        stdout.contains("the world builds: 78 buildings, 8 cars"),
        "{stdout}"
    );
    let scene = CityScene::read(&t.dir.join("out/city.json")).unwrap();
    assert_eq!(scene.buildings.len(), 78);
    assert_eq!(scene.half_extent_m, 250.0);
    assert!(scene.roads.length_m() > 1000.0);
    assert!(t.dir.join("out/city.png").is_file());
    // The import is deterministic, and the shipped scenario is what it makes.
    for file in ["city.json", "scenario.toml"] {
        let made = std::fs::read(t.dir.join("out").join(file)).unwrap();
        let kept = std::fs::read(shipped(file)).unwrap();
        assert!(
            made == kept,
            "scenarios/cities/helsinki/{file} is not what `fleet city` makes: import it again \
             (docs/cities.md)"
        );
    }
}

/// Flies the shipped city for `duration` seconds under `paper` and `setfleet` with `extra`
/// flags; checks that each run ends with every step, 0 violations, a car identified and its
/// pictures.
fn fly_both_variants(t: &TestRun, duration: u32, extra: &[&str]) {
    let duration_arg = duration.to_string();
    for variant in ["paper", "setfleet"] {
        let out_dir = t.dir.join(variant);
        let args = [
            &[
                "--duration",
                duration_arg.as_str(),
                "--variant",
                variant,
                "--strict",
            ][..],
            extra,
        ]
        .concat();
        let out = ChildGuard::spawn(&mut fleet_run(
            t,
            &shipped("scenario.toml"),
            &out_dir,
            &args,
        ))
        .wait_timeout(EXIT_TIMEOUT * 3)
        .expect("the run ends");
        assert!(
            out.status.success(),
            "{variant}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let s = summary(&out_dir);
        assert_eq!(s["violations"], 0, "{variant}: {s}");
        assert_eq!(s["steps"], u64::from(duration) * 2, "{variant}: {s}");
        let identified = s["identified_final"].as_f64().expect("identified_final");
        assert!(identified >= 1.0, "{variant}: {s}");
        assert!(out_dir.join("sets.png").is_file());
    }
}

#[test]
fn the_imported_city_flies_with_every_target_in_its_set() {
    fly_both_variants(&TestRun::new("city-run"), 40, &[]);
}

/// SUMO drives the cars (`city.traffic = "sumo"`): the fleet flies them with every target in
/// its set. `.ci/run` installs SUMO; where it is missing this test fails, saying how to
/// install it.
#[test]
fn sumo_drives_the_imported_city_with_every_target_in_its_set() {
    fly_both_variants(
        &TestRun::new("city-sumo"),
        30,
        &["--set", "city.traffic=\"sumo\""],
    );
}

/// A trace that breaks the estimator's assumptions, and SUMO where it is missing, stop the run
/// before it starts (exit 2), saying which car when, or how to install SUMO.
#[test]
fn a_bad_trace_or_a_missing_sumo_is_refused_before_the_run_starts() {
    let t = TestRun::new("city-trace");
    // A road point of the scene (8.8 m or more from every building), and a car that jumps 5 m
    // from it at 0.5 s.
    let scene: Value =
        serde_json::from_str(&std::fs::read_to_string(shipped("city.json")).unwrap()).unwrap();
    let p = &scene["roads"]["points"][0];
    let (x, y) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
    let inward = if x > 0.0 { -5.0 } else { 5.0 };
    let trace = t.write(
        "jump.csv",
        &format!(
            "time_s,car,x_m,y_m,heading_rad\n0,0,{x},{y},0\n0.5,0,{},{y},0\n1,0,{},{y},0\n",
            x + inward,
            x + inward
        ),
    );
    let trace_key = format!("city.trace={:?}", trace.display().to_string());
    let out = run_to_end(&mut fleet_run(
        &t,
        &shipped("scenario.toml"),
        &t.dir.join("out"),
        &[
            "--duration",
            "1",
            "--set",
            "targets.count=1",
            "--set",
            "city.traffic=\"trace\"",
            "--set",
            &trace_key,
        ],
    ));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("car 0 moves 5.000000 m from 0 s to 0.5 s"),
        "{stderr}"
    );
    let out = run_to_end(
        fleet_run(
            &t,
            &shipped("scenario.toml"),
            &t.dir.join("out"),
            &["--set", "city.traffic=\"sumo\""],
        )
        .env("SUMO_HOME", t.dir.join("no-sumo"))
        .env("PATH", "/usr/bin:/bin"),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("pip install eclipse-sumo==1.28.0"),
        "{stderr}"
    );
}

#[test]
fn a_scene_that_does_not_fit_the_run_is_refused_before_it_starts() {
    let t = TestRun::new("city-misfit");
    let cases: [(&[&str], &str); 3] = [
        (
            &["--set", "targets.building_clearance_m=9"],
            "import the city again with this scenario",
        ),
        (
            &["--set", "region.half_extent_m=300"],
            "half extent of 250 m",
        ),
        (&["--set", "city.scene=\"missing.json\""], "city.scene"),
    ];
    for (flags, message) in cases {
        let out = run_to_end(&mut fleet_run(
            &t,
            &shipped("scenario.toml"),
            &t.dir.join("out"),
            flags,
        ));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flags:?}: {stderr}");
        assert!(stderr.contains(message), "{flags:?}: {stderr}");
    }
}

#[test]
fn bad_input_exits_with_code_2_and_says_why() {
    let t = TestRun::new("city-bad");
    let not_pbf = t.write("map.osm.pbf", "<osm version=\"0.6\"></osm>\n");
    let cases: [(&std::path::Path, &[&str], &str); 5] = [
        (
            &not_pbf,
            &["--center", "60.1716,24.9443"],
            "not a readable OpenStreetMap PBF file",
        ),
        (
            &extract(),
            &["--center", "61.0,24.9443"],
            "lies outside the file's data",
        ),
        (&extract(), &["--center", "60.1716"], "expected LAT,LON"),
        (
            &extract(),
            &["--center", "60.1730,24.9410", "--half-extent", "10"],
            "--half-extent 10: must be more than",
        ),
        // A square of 30 m in the middle of a block: no road reaches into it.
        (
            &extract(),
            &["--center", "60.1730,24.9410", "--half-extent", "30"],
            "no drivable road",
        ),
    ];
    for (osm, flags, message) in cases {
        let out = fleet_city(&t, osm, flags);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flags:?}: {stderr}");
        assert!(stderr.contains(message), "{flags:?}: {stderr}");
    }
}

/// More cars than the roads hold apart: `fleet city` refuses a square whose roads cannot
/// place them all under the world's model, and `fleet run` refuses the drive when SUMO cannot
/// fit them in, both with exit code 2 and a message that says so. The 60 m square around the
/// centre has 333 m of road: the world's model places 58 cars 5.1 m apart (cars 0 to 57), SUMO fewer.
#[test]
fn more_cars_than_the_roads_hold_apart_are_refused() {
    let t = TestRun::new("city-crowd");
    let square = ["--center", "60.1716,24.9443", "--half-extent", "60"];
    let out = fleet_city(
        &t,
        &extract(),
        &[&square[..], &["--set", "targets.count=128"]].concat(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("cannot place car 58 of targets.count = 128"),
        "{stderr}"
    );

    let out = fleet_city(
        &t,
        &extract(),
        &[&square[..], &["--set", "targets.count=40"]].concat(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = run_to_end(&mut fleet_run(
        &t,
        &t.dir.join("out/scenario.toml"),
        &t.dir.join("run"),
        &["--duration", "1", "--set", "city.traffic=\"sumo\""],
    ));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("of the 40 cars in") && stderr.contains("lower targets.count"),
        "{stderr}"
    );
}
