//! `fleet city` imports the shipped extract into a scene the `city` crate reads back, and
//! refuses bad input with exit code 2 and a message that says what is wrong.

use std::path::PathBuf;
use std::process::Command;

use city::scene::CityScene;
use tests::{TestRun, binary, run_to_end};

fn extract() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/cities/helsinki.osm.pbf")
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
    let scene = CityScene::read(&t.dir.join("out/city.json")).unwrap();
    assert_eq!(scene.buildings.len(), 78);
    assert_eq!(scene.half_extent_m, 250.0);
    assert!(scene.roads.length_m() > 1000.0);
    assert!(t.dir.join("out/city.png").is_file());
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
