//! The scenario file as a user meets it: files, overrides, errors and the resolved dump.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use protocol::scenario::{Scenario, ScenarioError};

/// The design document, whose §5 shows the default scenario as a TOML block.
const DESIGN: &str = include_str!("../../docs/design.md");

/// The TOML block of the design document's §5.
fn design_example() -> &'static str {
    let start = DESIGN
        .find("```toml\n")
        .expect("a TOML block in docs/design.md")
        + 8;
    let len = DESIGN[start..].find("```").expect("the block ends");
    &DESIGN[start..start + len]
}

fn overrides(texts: &[&str]) -> Vec<String> {
    texts.iter().map(|t| (*t).to_owned()).collect()
}

fn with_overrides(texts: &[&str]) -> Result<Scenario, ScenarioError> {
    Scenario::load(None, &overrides(texts))
}

/// A scratch file in the system temp directory, removed on drop.
struct TempFile(PathBuf);

impl TempFile {
    fn new(name: &str, text: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("setfleet-scenario-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("create the temp dir");
        let path = dir.join(name);
        std::fs::write(&path, text).expect("write the temp file");
        Self(path)
    }

    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[test]
fn empty_text_and_no_file_are_the_default() {
    assert_eq!(Scenario::from_toml_str("").unwrap(), Scenario::default());
    assert_eq!(
        Scenario::from_toml_str("# nothing\n").unwrap(),
        Scenario::default()
    );
    assert_eq!(Scenario::load(None, &[]).unwrap(), Scenario::default());
}

#[test]
fn design_example_is_the_default() {
    assert_eq!(
        Scenario::from_toml_str(design_example()).unwrap(),
        Scenario::default()
    );
}

#[test]
fn integers_are_accepted_where_floats_are_expected() {
    let s = Scenario::from_toml_str("duration_s = 60\n[region]\nbuilding_height_m = [10, 60]\n")
        .unwrap();
    assert_eq!(s.duration_s, 60.0);
    assert_eq!(s.region.building_height_m, [10.0, 60.0]);
}

#[test]
fn file_then_overrides_in_order() {
    let file = TempFile::new(
        "file_then_overrides.toml",
        "seed = 7\n[guidance]\nkappa = 0.5\n",
    );
    let s = Scenario::load(
        Some(file.path()),
        &overrides(&["guidance.kappa=2", "guidance.kappa=0"]),
    )
    .unwrap();
    assert_eq!(s.seed, 7);
    assert_eq!(s.guidance.kappa, 0.0);
}

#[test]
fn overrides_of_each_kind() {
    let s = with_overrides(&[
        "guidance.kappa=0",
        "uavs.altitudes_m=[80,90,100.5,110]",
        "guidance.use_map=false",
        "comms.range_m=inf",
        "duration_s=60",
        "seed=42",
        "camera.depth_noise=[-0.02, 0.03]",
        "timing={guidance_period_s=1.5}",
    ])
    .unwrap();
    assert_eq!(s.guidance.kappa, 0.0);
    assert_eq!(s.uavs.altitudes_m, vec![80.0, 90.0, 100.5, 110.0]);
    assert!(!s.guidance.use_map);
    assert_eq!(s.comms.range_m, f64::INFINITY);
    assert_eq!(s.duration_s, 60.0);
    assert_eq!(s.seed, 42);
    assert_eq!(s.camera.depth_noise, [-0.02, 0.03]);
    assert_eq!(s.timing.guidance_period_s, 1.5);
    assert_eq!(s.timing.cvs_period_s, 0.5);

    let finite = with_overrides(&["comms.range_m=150"]).unwrap();
    assert_eq!(finite.comms.range_m, 150.0);
}

#[test]
fn lossy_slow_links_are_set_from_the_command_line_and_checked() {
    let default = Scenario::default();
    assert_eq!((default.comms.loss, default.comms.latency_ms), (0.0, 0.0));
    let s = with_overrides(&["comms.loss=0.3", "comms.latency_ms=250"]).unwrap();
    assert_eq!((s.comms.loss, s.comms.latency_ms), (0.3, 250.0));
    let s = Scenario::from_toml_str("[comms]\nloss = 1\nlatency_ms = 0\n").unwrap();
    assert_eq!(s.comms.loss, 1.0);
    for (text, key, says) in [
        ("comms.loss=nan", "comms.loss", "0 <= value <= 1"),
        ("comms.loss=-0.1", "comms.loss", "0 <= value <= 1"),
        ("comms.loss=1.5", "comms.loss", "0 <= value <= 1"),
        ("comms.loss=inf", "comms.loss", "0 <= value <= 1"),
        (
            "comms.latency_ms=-1",
            "comms.latency_ms",
            "0 <= value <= 10000",
        ),
        (
            "comms.latency_ms=inf",
            "comms.latency_ms",
            "0 <= value <= 10000",
        ),
        (
            "comms.latency_ms=nan",
            "comms.latency_ms",
            "0 <= value <= 10000",
        ),
        (
            "comms.latency_ms=20000",
            "comms.latency_ms",
            "0 <= value <= 10000",
        ),
    ] {
        let e = with_overrides(&[text]).unwrap_err();
        assert!(
            matches!(&e, ScenarioError::OutOfRange { key: k, .. } if k == key),
            "{text}: {e:?}"
        );
        let message = e.to_string();
        assert!(
            message.contains(key) && message.contains(says),
            "{text}: {message}"
        );
    }
    let e = with_overrides(&["comms.loss=\"high\""]).unwrap_err();
    assert!(
        matches!(&e, ScenarioError::WrongType { key, .. } if key == "comms.loss"),
        "{e:?}"
    );
    // The resolved scenario keeps them.
    let s = with_overrides(&["comms.loss=0.125", "comms.latency_ms=1500"]).unwrap();
    assert_eq!(Scenario::from_toml_str(&s.to_toml_string()).unwrap(), s);
}

#[test]
fn unknown_nested_key_is_named_with_the_valid_keys() {
    let err = Scenario::from_toml_str("[guidance]\nkapa = 0\n").unwrap_err();
    match &err {
        ScenarioError::UnknownKey { key, expected } => {
            assert_eq!(key, "guidance.kapa");
            assert!(expected.contains(&"kappa".to_owned()), "{expected:?}");
        }
        other => panic!("expected UnknownKey, got {other:?}"),
    }
    let text = err.to_string();
    assert!(
        text.contains("`guidance.kapa`") && text.contains("[guidance]"),
        "{text}"
    );

    let top = Scenario::from_toml_str("sed = 1\n").unwrap_err();
    assert!(matches!(top, ScenarioError::UnknownKey { ref key, .. } if key == "sed"));
    assert!(top.to_string().contains("top-level keys"), "{top}");

    let section = Scenario::from_toml_str("[drones]\ncount = 3\n").unwrap_err();
    assert!(matches!(section, ScenarioError::UnknownKey { ref key, .. } if key == "drones"));

    let via_override = with_overrides(&["uavs.cnt=3"]).unwrap_err();
    assert!(matches!(via_override, ScenarioError::UnknownKey { ref key, .. } if key == "uavs.cnt"));
}

#[test]
fn wrong_types_are_named() {
    let cases = [
        (
            "[guidance]\nkappa = \"high\"\n",
            "guidance.kappa",
            "a number",
        ),
        ("[uavs]\ncount = 2.5\n", "uavs.count", "an integer"),
        ("[guidance]\nuse_map = 1\n", "guidance.use_map", "a boolean"),
        ("region = 5\n", "region", "a table"),
        (
            "[region]\nbuilding_height_m = [1.0, 2.0, 3.0]\n",
            "region.building_height_m",
            "2",
        ),
        (
            "[uavs]\naltitudes_m = [80, \"x\"]\n",
            "uavs.altitudes_m",
            "numbers",
        ),
        ("[camera]\nrows = [360]\n", "camera.rows", "an integer"),
        ("[targets]\nsize_m = 4.6\n", "targets.size_m", "array of 3"),
    ];
    for (text, expected_key, expected_kind) in cases {
        match Scenario::from_toml_str(text) {
            Err(
                ref err @ ScenarioError::WrongType {
                    ref key,
                    ref expected,
                    ..
                },
            ) => {
                assert_eq!(key, expected_key, "{text}");
                assert!(expected.contains(expected_kind), "{text}: {expected}");
                assert!(err.to_string().contains(expected_key), "{err}");
            }
            other => panic!("{text}: expected WrongType, got {other:?}"),
        }
    }
    let bare_word = with_overrides(&["guidance.kappa=high"]).unwrap_err();
    assert!(
        matches!(bare_word, ScenarioError::WrongType { ref key, ref found, .. }
            if key == "guidance.kappa" && found.contains("high")),
        "{bare_word:?}"
    );
}

#[test]
fn out_of_range_values_are_named_with_the_accepted_range() {
    let cases = [
        ("[guidance]\nkappa = -1.0\n", "guidance.kappa"),
        ("[uavs]\ncount = 0\n", "uavs.count"),
        ("[targets]\ncount = -1\n", "targets.count"),
        ("[camera]\nrows = 4294967296\n", "camera.rows"),
        ("seed = -3\n", "seed"),
        ("[comms]\nrange_m = -inf\n", "comms.range_m"),
        ("[region]\nhalf_extent_m = nan\n", "region.half_extent_m"),
        (
            "[timing]\nguidance_period_s = 1.25\n",
            "timing.guidance_period_s",
        ),
    ];
    for (text, expected_key) in cases {
        match Scenario::from_toml_str(text) {
            Err(
                ref err @ ScenarioError::OutOfRange {
                    ref key,
                    ref accepted,
                    ..
                },
            ) => {
                assert_eq!(key, expected_key, "{text}");
                assert!(!accepted.is_empty());
                assert!(err.to_string().contains(expected_key), "{err}");
            }
            other => panic!("{text}: expected OutOfRange, got {other:?}"),
        }
    }
    let err = with_overrides(&["guidance.kappa=-1"]).unwrap_err();
    assert_eq!(
        err.to_string(),
        "`guidance.kappa` = -1.0 is out of range; accepted: 0 <= value < inf"
    );
}

#[test]
fn bad_overrides_are_refused_with_the_text() {
    for text in [
        "guidance.kappa",
        "=3",
        "guidance.kappa=",
        "a..b=1",
        "uavs.altitudes_m=[1,",
    ] {
        match with_overrides(&[text]) {
            Err(
                ref err @ ScenarioError::BadOverride {
                    text: ref given, ..
                },
            ) => {
                assert_eq!(given, text);
                assert!(err.to_string().contains("KEY=VALUE"), "{err}");
            }
            other => panic!("{text}: expected BadOverride, got {other:?}"),
        }
    }
}

#[test]
fn syntax_errors_give_origin_line_and_column() {
    let err = Scenario::from_toml_str("seed = 1\n[region\n").unwrap_err();
    match err {
        ScenarioError::Syntax { origin, line, .. } => {
            assert_eq!(origin, "<string>");
            assert_eq!(line, 2);
        }
        other => panic!("expected Syntax, got {other:?}"),
    }
    let file = TempFile::new("syntax.toml", "seed = = 1\n");
    let err = Scenario::load(Some(file.path()), &[]).unwrap_err();
    assert!(
        matches!(err, ScenarioError::Syntax { ref origin, line: 1, column: 8, .. }
            if origin.ends_with("syntax.toml")),
        "{err:?}"
    );
}

#[test]
fn missing_file_is_a_read_error_naming_the_path() {
    let path = Path::new("/nonexistent/setfleet/scenario.toml");
    let err = Scenario::load(Some(path), &[]).unwrap_err();
    assert!(matches!(err, ScenarioError::Read { path: ref p, .. } if p == path));
    assert!(
        err.to_string()
            .contains("/nonexistent/setfleet/scenario.toml")
    );
}

#[test]
fn the_changes_alone_load_back_to_the_scenario() {
    assert_eq!(Scenario::default().to_toml_changes(), "");
    let changed = with_overrides(&[
        "seed=7",
        "comms.range_m=inf",
        "region.building_height_m=[3, 54]",
        "city.storey_height_m=3.5",
        "uavs.altitudes_m=[61.5, 70, 80.25, 90]",
    ])
    .unwrap();
    let text = changed.to_toml_changes();
    assert!(!text.contains("cvs_period_s"), "{text}");
    assert!(text.contains("storey_height_m = 3.5"), "{text}");
    assert_eq!(Scenario::from_toml_str(&text).unwrap(), changed);
}

#[test]
fn a_city_scene_is_taken_from_the_scenario_files_folder() {
    let file = TempFile::new(
        "city-scenario.toml",
        "[city]\nscene = \"helsinki/city.json\"\n",
    );
    let loaded = Scenario::load(Some(file.path()), &[]).unwrap();
    let folder = std::path::absolute(file.path().parent().unwrap()).unwrap();
    assert_eq!(
        Path::new(&loaded.city.scene),
        folder.join("helsinki/city.json")
    );
    // An override's relative path is the working directory's, made absolute.
    let set = with_overrides(&["city.scene=\"a/city.json\""]).unwrap();
    assert_eq!(
        Path::new(&set.city.scene),
        std::env::current_dir().unwrap().join("a/city.json")
    );
    // An absolute path stays as it is, and the generated city has none.
    let abs = with_overrides(&["city.scene=\"/srv/city.json\""]).unwrap();
    assert_eq!(abs.city.scene, "/srv/city.json");
    assert_eq!(Scenario::load(None, &[]).unwrap().city.scene, "");
}

#[test]
fn resolved_scenario_round_trips() {
    let default = Scenario::default();
    let text = default.to_toml_string();
    assert!(text.contains("range_m = inf"), "{text}");
    assert_eq!(Scenario::from_toml_str(&text).unwrap(), default);

    let changed = with_overrides(&[
        "seed=9223372036854775807",
        "comms.range_m=123.456",
        "uavs.altitudes_m=[61.5, 70, 80.25, 1e3]",
        "guidance.lambda=3.3e-7",
        "guidance.yaw_increments_rad=[-0.1, 0.1]",
        "guidance.use_map=false",
        "camera.unknown_fraction=0.1",
    ])
    .unwrap();
    let back = Scenario::from_toml_str(&changed.to_toml_string()).unwrap();
    assert_eq!(back, changed);
}

#[test]
fn unwritable_scenario_does_not_load_as_the_default() {
    let scenario = Scenario {
        seed: u64::MAX,
        ..Scenario::default()
    };
    assert!(scenario.validate().is_err());
    assert!(Scenario::from_toml_str(&scenario.to_toml_string()).is_err());
}

proptest! {
    #[test]
    fn arbitrary_override_strings_never_panic(text in any::<String>()) {
        let _ = with_overrides(&[&text]);
    }

    #[test]
    fn override_shaped_strings_never_panic(
        key in "(seed|duration_s|region|uavs\\.altitudes_m|camera\\.rows|guidance\\.[a-z_]{0,20}|[a-z.]{0,12})",
        value in "[ -~]{0,24}",
    ) {
        let _ = with_overrides(&[&format!("{key}={value}")]);
    }

    #[test]
    fn valid_numeric_overrides_round_trip(kappa in 0.0f64..1e6, range in 1.0f64..1e5, seed in 0u64..=i64::MAX as u64) {
        let s = with_overrides(&[
            &format!("guidance.kappa={kappa:?}"),
            &format!("comms.range_m={range:?}"),
            &format!("seed={seed}"),
        ]).unwrap();
        prop_assert_eq!(s.guidance.kappa, kappa);
        prop_assert_eq!(s.comms.range_m, range);
        prop_assert_eq!(&Scenario::from_toml_str(&s.to_toml_string()).unwrap(), &s);
    }
}

/// The calibrated scenario the repository ships (`scenarios/paper-calibrated.toml`,
/// docs/results/calibration.md) loads, and departs from the paper's scenario only in what the
/// paper leaves unstated: here the camera's tilt, 35 degrees below the horizon, and the UAVs'
/// speed, 15 m/s (7.5 times the cars' top speed, where the paper asks 5 or more).
#[test]
fn the_shipped_calibrated_scenario_changes_only_an_unstated_choice() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/paper-calibrated.toml");
    let calibrated = Scenario::load(Some(&path), &[]).expect("the calibrated scenario loads");
    assert_eq!(calibrated.camera.tilt_rad, 35f64.to_radians());
    assert!(calibrated.uavs.speed_mps >= 5.0 * calibrated.targets.max_speed_mps);
    let mut expected = Scenario::default();
    expected.camera.tilt_rad = calibrated.camera.tilt_rad;
    expected.uavs.speed_mps = 15.0;
    assert_eq!(calibrated, expected);
}

/// The second calibration (`scenarios/paper-fit.toml`, docs/results/calibration.md, "The
/// second calibration") loads, and departs from the paper's scenario only in what the paper
/// leaves unstated: the roofs' heights, how the cars' speeds are drawn and their stops, the
/// UAVs' speed (at least 5 times the cars' top speed) and altitudes (distinct, above every
/// roof), and the camera's tilt.
#[test]
fn the_shipped_fit_changes_only_unstated_choices() {
    use protocol::scenario::SpeedDraw;
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/paper-fit.toml");
    let fit = Scenario::load(Some(&path), &[]).expect("the fitted scenario loads");
    assert!(fit.uavs.speed_mps >= 5.0 * fit.targets.max_speed_mps);
    let roof = fit.region.building_height_m[1];
    assert!(fit.uavs.altitudes_m.iter().all(|&a| a > roof));
    let mut expected = Scenario::default();
    expected.region.building_height_m = [10.0, 20.0];
    expected.targets.speed_draw = SpeedDraw::PerStep;
    expected.targets.stops_per_min = 2.0;
    expected.targets.stop_s = [30.0, 120.0];
    expected.uavs.speed_mps = 20.0;
    expected.uavs.altitudes_m = vec![80.0, 90.0, 100.0, 110.0];
    expected.camera.tilt_rad = 35f64.to_radians();
    assert_eq!(fit, expected);
}
