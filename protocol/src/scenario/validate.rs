//! Checking a scenario: keys and types against the schema, then every value against its range.
//!
//! Two passes, because they see different things. The schema pass walks the user's TOML table
//! before serde touches it, so it can name the full dotted key of an unknown key or a wrong
//! type (serde's own errors cannot). The range pass runs on the typed [`Scenario`], so a
//! scenario built in code (the orchestrator's `--seed`, `--uavs`) is held to the same ranges as
//! one read from a file.

use std::f64::consts::PI;
use std::fmt;

use toml::{Table, Value};

use super::{Scenario, ScenarioError};
use crate::frame::{FRAME_MAX_BOXES, FRAME_MAX_PIXELS};
use crate::wire::{MAX_UAVS, TRUTH_MAX_TARGETS};
use sets::grid::GroundGrid;

/// Arrays whose length the user chooses; every other array has the length of its default.
const VARIABLE_LENGTH_ARRAYS: &[&str] = &[
    "uavs.altitudes_m",
    "guidance.yaw_increments_rad",
    "guidance.external_uavs",
];

/// Longest run, seconds (about 11.5 days of simulated time).
const MAX_DURATION_S: f64 = 1e6;
/// Finest bit-raster cell side, metres.
const MIN_CELL_M: f64 = 0.05;
/// Coarsest bit-raster cell side, metres.
const MAX_CELL_M: f64 = 10.0;
/// Bit-raster cells along one side of the RoI (20000^2 bits = 50 MB per set).
const MAX_CELLS_PER_SIDE: u32 = 20_000;
/// Most yaw increments in `U`.
const MAX_YAW_INCREMENTS: usize = 9;
/// Most control sequences `|U|^h` the MPC evaluates per decision.
const MAX_CONTROL_SEQUENCES: usize = 10_000;
/// Most periods the `setfleet` planner looks ahead.
const MAX_LOOKAHEAD_PERIODS: u32 = 16;
/// Widest beam of the `setfleet` planner.
const MAX_BEAM_WIDTH: u32 = 64;
/// Longest future growth the `setfleet` planner charges, and longest revisit period of its
/// tracking schedule, seconds.
const MAX_GROWTH_HORIZON_S: f64 = 600.0;
/// Smallest image side, pixels.
const MIN_IMAGE_SIDE: u32 = 8;
/// Longest link latency, milliseconds: every receiver and the observer hold the estimates in
/// flight, so a latency is memory (10 s is 20 steps of estimates by default).
pub const MAX_LATENCY_MS: f64 = 10_000.0;
/// Most times a measurement is forwarded (`comms.relay_hops`): each hop adds a step of
/// delay and the measurement's bytes to the forwarding agent's estimate.
pub const MAX_RELAY_HOPS: u32 = 8;
/// Longest wait for an external planner's answer, milliseconds: a minute, for a learning
/// planner that trains between its decisions. The world's lockstep wait and the token ring's
/// wait for a holder grow by it (`protocol::timeouts`), so a slow planner stalls the run rather
/// than being waited out.
pub const MAX_EXTERNAL_PLANNER_MS: u32 = 60_000;
/// Relative tolerance of "a whole number of CVS periods".
const PERIOD_MULTIPLE_TOLERANCE: f64 = 1e-9;

/// Targets a scenario may hold: as many as both a truth message and a frame can carry.
const MAX_TARGETS: usize = if TRUTH_MAX_TARGETS < FRAME_MAX_BOXES {
    TRUTH_MAX_TARGETS
} else {
    FRAME_MAX_BOXES
};

/// The accepted values of every string key.
pub(super) fn string_choices(key: &str) -> Option<&'static [&'static str]> {
    match key {
        "guidance.planner" => Some(&super::Planner::NAMES),
        "estimator.sets" => Some(&super::SetGrowth::NAMES),
        "estimator.depth_ray" => Some(&super::RayAssumption::NAMES),
        "camera.depth_ray" => Some(&super::DepthRay::NAMES),
        "targets.speed_draw" => Some(&super::SpeedDraw::NAMES),
        "city.traffic" => Some(&super::CityTraffic::NAMES),
        "guidance.hidden_resolution" => Some(&super::HiddenResolution::NAMES),
        "guidance.hidden_window" => Some(&super::HiddenWindow::NAMES),
        "guidance.predicted_views" => Some(&super::PredictedViews::NAMES),
        "guidance.border" => Some(&super::PlanBorder::NAMES),
        "guidance.set_resolution" => Some(&super::SetResolution::NAMES),
        "guidance.distance_from" => Some(&super::DistanceFrom::NAMES),
        "guidance.hidden_sets" => Some(&super::HiddenSets::NAMES),
        "guidance.sweep" => Some(&super::SweepPlan::NAMES),
        "comms.exchange" => Some(&super::Exchange::NAMES),
        "comms.token_range" => Some(&super::TokenRange::NAMES),
        "comms.liveness" => Some(&super::Liveness::NAMES),
        "guidance.external_request" => Some(&super::ExternalRequest::NAMES),
        _ => None,
    }
}

/// The accepted range of every integer key, inclusive.
///
/// The schema pass uses it before deserialising (a TOML integer is an `i64`, the fields are
/// `u32`/`u64`, so a value out of the field's type must be caught while the key is still known);
/// [`Scenario::validate`] uses it again on the typed values.
pub(super) fn integer_range(key: &str) -> Option<(i128, i128)> {
    let range = match key {
        // TOML integers are i64: a larger seed could not be written into the resolved scenario.
        "seed" => (0, i64::MAX as i128),
        "targets.count" => (0, MAX_TARGETS as i128),
        "uavs.count" => (1, MAX_UAVS as i128),
        "camera.rows" | "camera.cols" => (
            MIN_IMAGE_SIDE as i128,
            (FRAME_MAX_PIXELS / MIN_IMAGE_SIDE as usize) as i128,
        ),
        "camera.min_pixels" => (1, FRAME_MAX_PIXELS as i128),
        "guidance.horizon" => (1, 4),
        "guidance.lookahead_periods" => (1, MAX_LOOKAHEAD_PERIODS as i128),
        "guidance.beam_width" => (1, MAX_BEAM_WIDTH as i128),
        "comms.whole_sets_every" => (1, 10_000),
        "comms.relay_hops" => (0, MAX_RELAY_HOPS as i128),
        "timing.external_planner_ms" => (1, MAX_EXTERNAL_PLANNER_MS as i128),
        // Each element: a UAV index.
        "guidance.external_uavs" => (0, MAX_UAVS as i128 - 1),
        _ => return None,
    };
    Some(range)
}

/// Checks the keys and value kinds of `user` against `schema` (the default scenario as a
/// table), naming full dotted keys. Integers given where a float is expected become floats.
pub(super) fn check_keys_and_types(user: &mut Table, schema: &Table) -> Result<(), ScenarioError> {
    check_table(user, schema, "")
}

fn check_table(user: &mut Table, schema: &Table, prefix: &str) -> Result<(), ScenarioError> {
    for (name, value) in user.iter_mut() {
        let key = dotted(prefix, name);
        let Some(expected) = schema.get(name) else {
            return Err(unknown_key(key, schema));
        };
        check_value(value, expected, &key)?;
    }
    Ok(())
}

/// The error for `key`, absent from `level` (the schema table it would sit in).
pub(super) fn unknown_key(key: String, level: &Table) -> ScenarioError {
    let mut expected: Vec<String> = level.keys().cloned().collect();
    expected.sort();
    ScenarioError::UnknownKey { key, expected }
}

/// `prefix.name`, or `name` at the top level.
pub(super) fn dotted(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_owned()
    } else {
        format!("{prefix}.{name}")
    }
}

fn check_value(value: &mut Value, expected: &Value, key: &str) -> Result<(), ScenarioError> {
    match (expected, &mut *value) {
        (Value::Table(schema), Value::Table(user)) => check_table(user, schema, key),
        (Value::Float(_), Value::Float(_)) | (Value::Boolean(_), Value::Boolean(_)) => Ok(()),
        (Value::Float(_), Value::Integer(i)) => {
            // `duration_s = 60` means 60.0; serde would accept it too, but converting here
            // keeps the table that is deserialised, and any later dump of it, uniform.
            let as_float = *i as f64;
            *value = Value::Float(as_float);
            Ok(())
        }
        (Value::Integer(_), Value::Integer(i)) => check_integer(key, i128::from(*i)),
        (Value::String(_), Value::String(text)) => match string_choices(key) {
            Some(choices) if !choices.contains(&text.as_str()) => Err(ScenarioError::OutOfRange {
                key: key.to_owned(),
                value: format!("{text:?}"),
                accepted: format!("one of {}", choices.join(", ")),
            }),
            _ => Ok(()),
        },
        (Value::Array(schema), Value::Array(user)) => check_array(user, schema, key),
        (_, found) => Err(ScenarioError::WrongType {
            key: key.to_owned(),
            expected: describe_expected(expected, key),
            found: describe_found(found),
        }),
    }
}

fn check_array(user: &mut [Value], schema: &[Value], key: &str) -> Result<(), ScenarioError> {
    let fixed = !VARIABLE_LENGTH_ARRAYS.contains(&key);
    let wrong_type = |found: String| ScenarioError::WrongType {
        key: key.to_owned(),
        expected: describe_expected(&Value::Array(schema.to_vec()), key),
        found,
    };
    if fixed && user.len() != schema.len() {
        return Err(wrong_type(format!("an array of {} values", user.len())));
    }
    let Some(element) = schema.first() else {
        // Every array of the schema has a sample element (see `super::schema`).
        return Ok(());
    };
    for (index, item) in user.iter_mut().enumerate() {
        let kind_matches = matches!(
            (element, &*item),
            (Value::Float(_), Value::Float(_) | Value::Integer(_))
                | (Value::Integer(_), Value::Integer(_))
                | (Value::Boolean(_), Value::Boolean(_))
                | (Value::String(_), Value::String(_))
        );
        if !kind_matches {
            return Err(wrong_type(format!(
                "an array holding {} at index {index}",
                describe_found(item)
            )));
        }
        if let Value::Integer(i) = item {
            if element.is_float() {
                let as_float = *i as f64;
                *item = Value::Float(as_float);
            } else {
                // An integer array's elements have the key's range.
                check_integer(key, i128::from(*i))?;
            }
        }
    }
    Ok(())
}

fn describe_expected(expected: &Value, key: &str) -> String {
    match expected {
        Value::Float(_) => "a number (float or integer)".to_owned(),
        Value::Integer(_) => match integer_range(key) {
            Some((lo, hi)) => format!("an integer in {lo}..={hi}"),
            None => "an integer".to_owned(),
        },
        Value::Boolean(_) => "a boolean (true or false)".to_owned(),
        Value::String(_) => match string_choices(key) {
            Some(choices) => format!("a string, one of {}", choices.join(", ")),
            None => "a string".to_owned(),
        },
        Value::Datetime(_) => "a date-time".to_owned(),
        Value::Table(_) => "a table".to_owned(),
        Value::Array(items) => {
            let of = match items.first() {
                Some(Value::Float(_)) => "numbers",
                Some(Value::Integer(_)) => "integers",
                Some(Value::Boolean(_)) => "booleans",
                _ => "values",
            };
            if VARIABLE_LENGTH_ARRAYS.contains(&key) {
                format!("an array of {of}")
            } else {
                format!("an array of {} {of}", items.len())
            }
        }
    }
}

fn describe_found(found: &Value) -> String {
    match found {
        Value::Table(_) => "a table".to_owned(),
        Value::Array(items) => format!("an array of {} values", items.len()),
        other => {
            let mut shown = other.to_string();
            if shown.len() > 40 {
                let cut = (0..=37)
                    .rev()
                    .find(|&i| shown.is_char_boundary(i))
                    .unwrap_or(0);
                shown.truncate(cut);
                shown.push_str("...");
            }
            format!("{} {shown}", other.type_str())
        }
    }
}

fn check_integer(key: &str, value: i128) -> Result<(), ScenarioError> {
    match integer_range(key) {
        Some((lo, hi)) if !(lo..=hi).contains(&value) => Err(ScenarioError::OutOfRange {
            key: key.to_owned(),
            value: value.to_string(),
            accepted: format!("{lo} <= value <= {hi}"),
        }),
        _ => Ok(()),
    }
}

/// An interval of the real line; `hi = inf` with an open end means "finite".
#[derive(Clone, Copy, Debug)]
struct Interval {
    lo: f64,
    lo_open: bool,
    hi: f64,
    hi_open: bool,
}

impl Interval {
    /// `lo < value <= hi`.
    const fn open_closed(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            lo_open: true,
            hi,
            hi_open: false,
        }
    }

    /// `lo <= value <= hi`.
    const fn closed(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            lo_open: false,
            hi,
            hi_open: false,
        }
    }

    /// `lo <= value < hi`.
    const fn closed_open(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            lo_open: false,
            hi,
            hi_open: true,
        }
    }

    /// `lo < value < hi`.
    const fn open(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            lo_open: true,
            hi,
            hi_open: true,
        }
    }

    /// `0 < value < inf`.
    const POSITIVE: Self = Self::open(0.0, f64::INFINITY);
    /// `0 <= value < inf`.
    const NON_NEGATIVE: Self = Self::closed_open(0.0, f64::INFINITY);

    /// Whether `v` lies inside; NaN never does.
    fn contains(&self, v: f64) -> bool {
        let above = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        let below = if self.hi_open {
            v < self.hi
        } else {
            v <= self.hi
        };
        above && below
    }

    fn check(&self, key: &str, v: f64) -> Result<(), ScenarioError> {
        require(self.contains(v), key, v, self.to_string())
    }
}

impl fmt::Display for Interval {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lo = if self.lo_open { "<" } else { "<=" };
        let hi = if self.hi_open { "<" } else { "<=" };
        write!(f, "{} {lo} value {hi} {}", self.lo, self.hi)
    }
}

/// `Ok` when `ok`, else the out-of-range error for `key`.
fn require(
    ok: bool,
    key: &str,
    value: impl fmt::Debug,
    accepted: impl Into<String>,
) -> Result<(), ScenarioError> {
    if ok {
        Ok(())
    } else {
        Err(ScenarioError::OutOfRange {
            key: key.to_owned(),
            value: format!("{value:?}"),
            accepted: accepted.into(),
        })
    }
}

impl Scenario {
    /// Checks every value against its accepted range, cross-key constraints included.
    ///
    /// The first value out of range is reported with its full dotted key, the value and the
    /// accepted range as text. Checks run in dependency order, so a constraint that involves
    /// two keys is only tested once both are individually sane.
    ///
    /// Beyond the plain ranges: the target model (radius `radius_m`, height
    /// `cylinder_height_m`) must contain the car `size_m`; explicit UAV altitudes must be
    /// distinct and above every building; the top image row must look below the horizon; the
    /// guidance period must be a whole number of CVS periods; the run must last at least one
    /// CVS period; `seed` must fit a TOML integer (at most `i64::MAX`) so that the resolved
    /// scenario can be written back.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        check_integer("seed", i128::from(self.seed))?;
        Interval::open_closed(0.0, MAX_DURATION_S).check("duration_s", self.duration_s)?;
        self.validate_region()?;
        self.validate_city()?;
        self.validate_targets()?;
        self.validate_uavs()?;
        self.validate_camera()?;
        self.validate_timing()?;
        self.validate_estimator()?;
        self.validate_guidance()?;
        self.validate_comms()
    }

    fn validate_comms(&self) -> Result<(), ScenarioError> {
        let comms = &self.comms;
        Interval::open_closed(0.0, f64::INFINITY).check("comms.range_m", comms.range_m)?;
        Interval::closed(0.0, 1.0).check("comms.loss", comms.loss)?;
        Interval::closed(0.0, MAX_LATENCY_MS).check("comms.latency_ms", comms.latency_ms)?;
        check_integer("comms.whole_sets_every", i128::from(comms.whole_sets_every))?;
        check_integer("comms.relay_hops", i128::from(comms.relay_hops))
    }

    fn validate_region(&self) -> Result<(), ScenarioError> {
        let region = &self.region;
        Interval::closed(20.0, 5000.0).check("region.half_extent_m", region.half_extent_m)?;
        Interval::closed(0.0, 0.3).check("region.building_fraction", region.building_fraction)?;
        Interval::closed(4.0, 200.0).check("region.lot_size_m", region.lot_size_m)?;
        let [lo, hi] = region.building_height_m;
        require(
            lo > 0.0 && lo <= hi && hi <= 500.0,
            "region.building_height_m",
            region.building_height_m,
            "[lo, hi] with 0 < lo <= hi <= 500",
        )
    }

    fn validate_city(&self) -> Result<(), ScenarioError> {
        let city = &self.city;
        Interval::closed(1.0, 10.0).check("city.storey_height_m", city.storey_height_m)?;
        Interval::closed(1.0, 500.0).check("city.default_height_m", city.default_height_m)?;
        if city.traffic != super::CityTraffic::Roads {
            require(
                !city.scene.is_empty(),
                "city.traffic",
                format!("{:?}", city.traffic).to_lowercase(),
                "\"roads\" without city.scene: SUMO and traces drive an imported city's cars",
            )?;
        }
        require(
            (city.traffic == super::CityTraffic::Trace) != city.trace.is_empty(),
            "city.trace",
            &city.trace,
            "a file exactly when city.traffic = \"trace\"",
        )
    }

    fn validate_targets(&self) -> Result<(), ScenarioError> {
        let targets = &self.targets;
        check_integer("targets.count", i128::from(targets.count))?;
        Interval::open_closed(0.0, 50.0).check("targets.max_speed_mps", targets.max_speed_mps)?;
        Interval::closed_open(0.0, 1.0).check("targets.cruise_spread", targets.cruise_spread)?;
        Interval::POSITIVE.check("targets.radius_m", targets.radius_m)?;
        Interval::POSITIVE.check("targets.cylinder_height_m", targets.cylinder_height_m)?;
        let [length, width, height] = targets.size_m;
        let half_diagonal = 0.5 * length.hypot(width);
        require(
            targets
                .size_m
                .iter()
                .all(|&s| Interval::POSITIVE.contains(s))
                && half_diagonal <= targets.radius_m
                && height <= targets.cylinder_height_m,
            "targets.size_m",
            targets.size_m,
            format!(
                "[length, width, height], each finite and > 0, such that the target model \
                 contains the car: half the diagonal of length x width (here {half_diagonal:.3} m) \
                 <= targets.radius_m ({} m) and height <= targets.cylinder_height_m ({} m)",
                targets.radius_m, targets.cylinder_height_m
            ),
        )?;
        Interval::POSITIVE.check("targets.safety_distance_m", targets.safety_distance_m)?;
        Interval::closed(0.0, 60.0).check("targets.stops_per_min", targets.stops_per_min)?;
        let [lo, hi] = targets.stop_s;
        require(
            lo >= 0.0 && lo <= hi && hi <= 600.0,
            "targets.stop_s",
            targets.stop_s,
            "[lo, hi] with 0 <= lo <= hi <= 600",
        )?;
        let clearance = targets.building_clearance_m;
        require(
            clearance.is_finite() && clearance >= targets.safety_distance_m && clearance <= 100.0,
            "targets.building_clearance_m",
            clearance,
            format!(
                "targets.safety_distance_m ({} m) <= value <= 100: the paper keeps cars more \
                 than r_s from buildings",
                targets.safety_distance_m
            ),
        )
    }

    fn validate_uavs(&self) -> Result<(), ScenarioError> {
        let uavs = &self.uavs;
        check_integer("uavs.count", i128::from(uavs.count))?;
        Interval::open_closed(0.0, 100.0).check("uavs.speed_mps", uavs.speed_mps)?;
        Interval::open_closed(0.0, 10.0).check("uavs.max_yaw_rate_rps", uavs.max_yaw_rate_rps)?;
        Interval::open_closed(0.0, 100.0).check("uavs.altitude_step_m", uavs.altitude_step_m)?;
        let roof = self.region.building_height_m[1];
        let above_roofs = Interval::open(roof, f64::INFINITY);
        let altitudes = &uavs.altitudes_m;
        let distinct = altitudes
            .iter()
            .enumerate()
            .all(|(i, a)| altitudes[..i].iter().all(|b| a != b));
        require(
            altitudes.is_empty()
                || (altitudes.len() == uavs.count as usize
                    && altitudes.iter().all(|&a| above_roofs.contains(a))
                    && distinct),
            "uavs.altitudes_m",
            altitudes,
            format!(
                "[] (automatic), or exactly uavs.count ({}) distinct finite altitudes above \
                 every building (> region.building_height_m[1] = {roof} m)",
                uavs.count
            ),
        )
    }

    fn validate_camera(&self) -> Result<(), ScenarioError> {
        let camera = &self.camera;
        check_integer("camera.rows", i128::from(camera.rows))?;
        check_integer("camera.cols", i128::from(camera.cols))?;
        let pixels = u64::from(camera.rows) * u64::from(camera.cols);
        require(
            pixels <= FRAME_MAX_PIXELS as u64,
            "camera.cols",
            camera.cols,
            format!(
                "value >= {MIN_IMAGE_SIDE} and camera.rows x value <= {FRAME_MAX_PIXELS} \
                 pixels (the frame's capacity); camera.rows is {}",
                camera.rows
            ),
        )?;
        let aperture = Interval::open_closed(0.0, 0.9 * PI);
        require(
            aperture.contains(camera.aperture_rad),
            "camera.aperture_rad",
            camera.aperture_rad,
            format!("{aperture} (0.9 pi)"),
        )?;
        let tilt = Interval::open_closed(0.0, 0.5 * PI);
        let half_vertical = self.camera_model().vertical_half_aperture();
        require(
            tilt.contains(camera.tilt_rad) && camera.tilt_rad > half_vertical,
            "camera.tilt_rad",
            camera.tilt_rad,
            format!(
                "{tilt} (pi/2), and greater than the vertical half aperture \
                 ({half_vertical:.6} rad for these rows, cols and aperture) so that the top \
                 image row looks below the horizon"
            ),
        )?;
        let [lo, hi] = camera.depth_noise;
        require(
            lo > -1.0 && lo <= hi && hi < 1.0,
            "camera.depth_noise",
            camera.depth_noise,
            "[lo, hi] with -1 < lo <= hi < 1",
        )?;
        Interval::closed_open(0.0, 1.0)
            .check("camera.unknown_fraction", camera.unknown_fraction)?;
        require(
            camera.min_pixels >= 1 && u64::from(camera.min_pixels) <= pixels,
            "camera.min_pixels",
            camera.min_pixels,
            format!("1 <= value <= camera.rows x camera.cols ({pixels})"),
        )
    }

    fn validate_timing(&self) -> Result<(), ScenarioError> {
        let timing = &self.timing;
        Interval::open_closed(0.0, 10.0).check("timing.cvs_period_s", timing.cvs_period_s)?;
        let periods = timing.guidance_period_s / timing.cvs_period_s;
        let whole = periods.round();
        require(
            timing.guidance_period_s.is_finite()
                && whole >= 1.0
                && (timing.guidance_period_s - whole * timing.cvs_period_s).abs()
                    <= PERIOD_MULTIPLE_TOLERANCE * timing.guidance_period_s,
            "timing.guidance_period_s",
            timing.guidance_period_s,
            format!(
                "a whole multiple of timing.cvs_period_s ({0} s): {0}, {1}, {2}, ...",
                timing.cvs_period_s,
                2.0 * timing.cvs_period_s,
                3.0 * timing.cvs_period_s
            ),
        )?;
        check_integer(
            "timing.external_planner_ms",
            i128::from(timing.external_planner_ms),
        )?;
        require(
            self.duration_s >= timing.cvs_period_s,
            "duration_s",
            self.duration_s,
            format!(
                "timing.cvs_period_s ({} s) <= value <= {MAX_DURATION_S}: at least one step",
                timing.cvs_period_s
            ),
        )
    }

    fn validate_estimator(&self) -> Result<(), ScenarioError> {
        let estimator = &self.estimator;
        let cell = Interval::closed(MIN_CELL_M, MAX_CELL_M);
        cell.check("estimator.cell_m", estimator.cell_m)?;
        let per_side = GroundGrid::new(self.region.half_extent_m, estimator.cell_m).nx;
        require(
            per_side <= MAX_CELLS_PER_SIDE,
            "estimator.cell_m",
            estimator.cell_m,
            format!(
                "{cell}, and at most {MAX_CELLS_PER_SIDE} cells per side of the RoI: \
                 value >= 2 x region.half_extent_m / {MAX_CELLS_PER_SIDE} = {} m",
                2.0 * self.region.half_extent_m / f64::from(MAX_CELLS_PER_SIDE)
            ),
        )?;
        require(
            estimator.oem_cell_m >= estimator.cell_m && estimator.oem_cell_m.is_finite(),
            "estimator.oem_cell_m",
            estimator.oem_cell_m,
            format!("estimator.cell_m ({} m) <= value < inf", estimator.cell_m),
        )?;
        Interval::open_closed(0.0, f64::INFINITY).check("estimator.window_m", estimator.window_m)
    }

    fn validate_guidance(&self) -> Result<(), ScenarioError> {
        let guidance = &self.guidance;
        check_integer("guidance.horizon", i128::from(guidance.horizon))?;
        let increments = &guidance.yaw_increments_rad;
        let sequences = u32::try_from(increments.len())
            .ok()
            .and_then(|n| n.checked_pow(guidance.horizon));
        let yaw = Interval::closed(-PI, PI);
        require(
            (1..=MAX_YAW_INCREMENTS).contains(&increments.len())
                && increments.iter().all(|&u| yaw.contains(u))
                && sequences.is_some_and(|n| n as usize <= MAX_CONTROL_SEQUENCES),
            "guidance.yaw_increments_rad",
            increments,
            format!(
                "1 to {MAX_YAW_INCREMENTS} values, each in [-pi, pi], with at most \
                 {MAX_CONTROL_SEQUENCES} control sequences (count ^ guidance.horizon)"
            ),
        )?;
        Interval::NON_NEGATIVE.check("guidance.lambda", guidance.lambda)?;
        Interval::NON_NEGATIVE.check("guidance.kappa", guidance.kappa)?;
        let setfleet = &guidance.setfleet;
        check_integer(
            "guidance.lookahead_periods",
            i128::from(setfleet.lookahead_periods),
        )?;
        check_integer("guidance.beam_width", i128::from(setfleet.beam_width))?;
        Interval::NON_NEGATIVE.check("guidance.target_weight", setfleet.target_weight)?;
        Interval::closed(0.0, MAX_GROWTH_HORIZON_S)
            .check("guidance.growth_horizon_s", setfleet.growth_horizon_s)?;
        Interval::closed(0.0, 1e4).check("guidance.spread_m", setfleet.spread_m)?;
        Interval::closed(0.0, MAX_GROWTH_HORIZON_S)
            .check("guidance.track_revisit_s", setfleet.track_revisit_s)?;
        let uavs = self.uavs.count;
        let external = &guidance.external_uavs;
        let mut sorted = external.clone();
        sorted.sort_unstable();
        sorted.dedup();
        require(
            sorted.len() == external.len() && external.iter().all(|&u| u < uavs),
            "guidance.external_uavs",
            external,
            format!(
                "distinct UAVs of the fleet (0 to {})",
                uavs.saturating_sub(1)
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn out_of_range_key(scenario: &Scenario) -> String {
        match scenario.validate() {
            Err(ScenarioError::OutOfRange { key, .. }) => key,
            other => format!("not out of range: {other:?}"),
        }
    }

    #[test]
    fn default_is_valid() {
        assert!(Scenario::default().validate().is_ok());
    }

    #[test]
    fn every_integer_key_of_the_schema_has_a_range() {
        fn walk(table: &Table, prefix: &str, missing: &mut Vec<String>) {
            for (name, value) in table {
                let key = dotted(prefix, name);
                match value {
                    Value::Table(inner) => walk(inner, &key, missing),
                    Value::Integer(_) if integer_range(&key).is_none() => missing.push(key),
                    _ => {}
                }
            }
        }
        let mut missing = Vec::new();
        walk(&super::super::schema().unwrap(), "", &mut missing);
        assert!(
            missing.is_empty(),
            "integer keys without a range: {missing:?}"
        );
    }

    #[test]
    fn variable_length_arrays_are_exactly_the_vec_fields() {
        // A fixed array of the struct rejects one more element; a Vec accepts it.
        fn walk(table: &Table, prefix: &str, arrays: &mut Vec<(String, Vec<Value>)>) {
            for (name, value) in table {
                let key = dotted(prefix, name);
                match value {
                    Value::Table(inner) => walk(inner, &key, arrays),
                    Value::Array(items) => arrays.push((key, items.clone())),
                    _ => {}
                }
            }
        }
        let schema = super::super::schema().unwrap();
        let mut arrays = Vec::new();
        walk(&schema, "", &mut arrays);
        assert!(arrays.len() >= 5);
        for (key, items) in arrays {
            let mut table = schema.clone();
            let (section, name) = key.split_once('.').unwrap();
            let section = table.get_mut(section).unwrap().as_table_mut().unwrap();
            // One element more than the default, each of the kind of its sample element.
            section.insert(
                name.to_owned(),
                Value::Array(vec![items[0].clone(); items.len() + 1]),
            );
            let serde_accepts = table.try_into::<Scenario>().is_ok();
            assert_eq!(
                serde_accepts,
                VARIABLE_LENGTH_ARRAYS.contains(&key.as_str()),
                "{key}"
            );
        }
    }

    #[test]
    fn interval_text_reads_as_a_range() {
        assert_eq!(
            Interval::open_closed(0.0, 100.0).to_string(),
            "0 < value <= 100"
        );
        assert_eq!(Interval::NON_NEGATIVE.to_string(), "0 <= value < inf");
        assert!(!Interval::NON_NEGATIVE.contains(f64::NAN));
        assert!(!Interval::NON_NEGATIVE.contains(f64::INFINITY));
        assert!(Interval::open_closed(0.0, f64::INFINITY).contains(f64::INFINITY));
    }

    #[test]
    fn each_range_rejects_its_bad_values() {
        type Edit = fn(&mut Scenario);
        let cases: &[(&str, Edit)] = &[
            ("duration_s", |s| s.duration_s = 0.0),
            ("duration_s", |s| s.duration_s = f64::INFINITY),
            ("duration_s", |s| s.duration_s = 0.1),
            ("region.half_extent_m", |s| s.region.half_extent_m = 10.0),
            ("region.building_fraction", |s| {
                s.region.building_fraction = 0.5
            }),
            ("region.building_height_m", |s| {
                s.region.building_height_m = [70.0, 60.0]
            }),
            ("region.building_height_m", |s| {
                s.region.building_height_m = [0.0, 60.0]
            }),
            ("targets.count", |s| {
                s.targets.count = MAX_TARGETS as u32 + 1
            }),
            ("targets.max_speed_mps", |s| s.targets.max_speed_mps = 0.0),
            ("targets.cruise_spread", |s| s.targets.cruise_spread = 1.0),
            ("targets.cruise_spread", |s| s.targets.cruise_spread = -0.1),
            ("targets.size_m", |s| s.targets.size_m = [6.0, 2.0, 1.5]),
            ("targets.size_m", |s| s.targets.size_m = [4.6, 1.8, 2.5]),
            ("targets.size_m", |s| s.targets.size_m = [4.6, -1.0, 1.5]),
            ("targets.radius_m", |s| s.targets.radius_m = f64::NAN),
            ("targets.safety_distance_m", |s| {
                s.targets.safety_distance_m = 0.0
            }),
            ("targets.building_clearance_m", |s| {
                s.targets.building_clearance_m = 2.9
            }),
            ("targets.stops_per_min", |s| s.targets.stops_per_min = -1.0),
            ("targets.stops_per_min", |s| s.targets.stops_per_min = 61.0),
            ("targets.stop_s", |s| s.targets.stop_s = [10.0, 5.0]),
            ("targets.stop_s", |s| s.targets.stop_s = [f64::NAN, 5.0]),
            ("targets.stop_s", |s| s.targets.stop_s = [0.0, 601.0]),
            ("targets.building_clearance_m", |s| {
                s.targets.building_clearance_m = f64::NAN
            }),
            ("uavs.count", |s| s.uavs.count = 0),
            ("uavs.count", |s| s.uavs.count = MAX_UAVS as u32 + 1),
            ("uavs.speed_mps", |s| s.uavs.speed_mps = 101.0),
            ("uavs.altitudes_m", |s| {
                s.uavs.altitudes_m = vec![80.0, 90.0]
            }),
            ("uavs.altitudes_m", |s| {
                s.uavs.altitudes_m = vec![80.0, 90.0, 100.0, 80.0]
            }),
            ("uavs.altitudes_m", |s| {
                s.uavs.altitudes_m = vec![80.0, 90.0, 100.0, 50.0]
            }),
            ("uavs.altitudes_m", |s| {
                s.uavs.altitudes_m = vec![80.0, 90.0, 100.0, f64::INFINITY]
            }),
            ("uavs.altitude_step_m", |s| s.uavs.altitude_step_m = 0.0),
            ("uavs.altitude_step_m", |s| {
                s.uavs.altitude_step_m = f64::NAN
            }),
            ("uavs.altitude_step_m", |s| s.uavs.altitude_step_m = 101.0),
            ("uavs.max_yaw_rate_rps", |s| s.uavs.max_yaw_rate_rps = 11.0),
            ("camera.rows", |s| s.camera.rows = 4),
            ("camera.cols", |s| s.camera.cols = 481),
            ("camera.aperture_rad", |s| s.camera.aperture_rad = PI),
            ("camera.tilt_rad", |s| s.camera.tilt_rad = 0.2),
            ("camera.tilt_rad", |s| s.camera.tilt_rad = 1.6),
            ("camera.depth_noise", |s| s.camera.depth_noise = [0.1, -0.1]),
            ("camera.depth_noise", |s| s.camera.depth_noise = [-1.0, 0.0]),
            ("camera.unknown_fraction", |s| {
                s.camera.unknown_fraction = 1.0
            }),
            ("camera.min_pixels", |s| s.camera.min_pixels = 0),
            ("timing.cvs_period_s", |s| s.timing.cvs_period_s = 0.0),
            ("timing.guidance_period_s", |s| {
                s.timing.guidance_period_s = 3.2
            }),
            ("timing.guidance_period_s", |s| {
                s.timing.guidance_period_s = 0.2
            }),
            ("estimator.cell_m", |s| s.estimator.cell_m = 0.01),
            ("estimator.cell_m", |s| {
                s.region.half_extent_m = 5000.0;
                s.estimator.cell_m = 0.4;
            }),
            ("estimator.oem_cell_m", |s| s.estimator.oem_cell_m = 0.25),
            ("estimator.window_m", |s| s.estimator.window_m = 0.0),
            ("estimator.window_m", |s| s.estimator.window_m = f64::NAN),
            ("guidance.horizon", |s| s.guidance.horizon = 5),
            ("guidance.yaw_increments_rad", |s| {
                s.guidance.yaw_increments_rad.clear()
            }),
            ("guidance.yaw_increments_rad", |s| {
                s.guidance.yaw_increments_rad = vec![0.0; 10]
            }),
            ("guidance.yaw_increments_rad", |s| {
                s.guidance.yaw_increments_rad = vec![4.0]
            }),
            ("guidance.lambda", |s| s.guidance.lambda = -1.0),
            ("guidance.kappa", |s| s.guidance.kappa = f64::INFINITY),
            ("guidance.lookahead_periods", |s| {
                s.guidance.setfleet.lookahead_periods = 0
            }),
            ("guidance.lookahead_periods", |s| {
                s.guidance.setfleet.lookahead_periods = 17
            }),
            ("guidance.beam_width", |s| {
                s.guidance.setfleet.beam_width = 0
            }),
            ("guidance.beam_width", |s| {
                s.guidance.setfleet.beam_width = 65
            }),
            ("comms.whole_sets_every", |s| s.comms.whole_sets_every = 0),
            ("comms.relay_hops", |s| {
                s.comms.relay_hops = MAX_RELAY_HOPS + 1
            }),
            ("timing.external_planner_ms", |s| {
                s.timing.external_planner_ms = 0
            }),
            ("timing.external_planner_ms", |s| {
                s.timing.external_planner_ms = MAX_EXTERNAL_PLANNER_MS + 1
            }),
            ("guidance.external_uavs", |s| {
                s.guidance.external_uavs = vec![4]
            }),
            ("guidance.external_uavs", |s| {
                s.guidance.external_uavs = vec![1, 1]
            }),
            ("guidance.target_weight", |s| {
                s.guidance.setfleet.target_weight = -1.0
            }),
            ("guidance.growth_horizon_s", |s| {
                s.guidance.setfleet.growth_horizon_s = 601.0
            }),
            ("guidance.spread_m", |s| {
                s.guidance.setfleet.spread_m = f64::NAN
            }),
            ("guidance.track_revisit_s", |s| {
                s.guidance.setfleet.track_revisit_s = -1.0
            }),
            ("guidance.track_revisit_s", |s| {
                s.guidance.setfleet.track_revisit_s = f64::INFINITY
            }),
            ("comms.range_m", |s| s.comms.range_m = 0.0),
            ("comms.range_m", |s| s.comms.range_m = f64::NAN),
            ("comms.loss", |s| s.comms.loss = f64::NAN),
            ("comms.loss", |s| s.comms.loss = -0.01),
            ("comms.loss", |s| s.comms.loss = 1.01),
            ("comms.loss", |s| s.comms.loss = f64::INFINITY),
            ("comms.latency_ms", |s| s.comms.latency_ms = f64::NAN),
            ("comms.latency_ms", |s| s.comms.latency_ms = -1.0),
            ("comms.latency_ms", |s| s.comms.latency_ms = f64::INFINITY),
            ("comms.latency_ms", |s| {
                s.comms.latency_ms = MAX_LATENCY_MS + 1.0
            }),
            ("seed", |s| s.seed = u64::MAX),
        ];
        for (key, edit) in cases {
            let mut scenario = Scenario::default();
            edit(&mut scenario);
            assert_eq!(out_of_range_key(&scenario), *key, "{scenario:?}");
        }
    }

    /// The depth-ray keys: the estimator assumes any ray of the pixel unless told, the world
    /// measures along the centre unless told, and each refuses other names.
    #[test]
    fn the_depth_ray_keys_default_to_the_paper_and_the_renderer() {
        use super::super::{DepthRay, RayAssumption};
        let s = Scenario::default();
        assert_eq!(s.estimator.depth_ray, RayAssumption::Any);
        assert_eq!(s.camera.depth_ray, DepthRay::Centre);
        assert_eq!(s.targets.building_clearance_m, 6.0);
        let set =
            |o: &[&str]| Scenario::load(None, &o.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        let s = set(&[
            "camera.depth_ray=\"random\"",
            "estimator.depth_ray=\"centre\"",
            "targets.building_clearance_m=3",
        ])
        .unwrap();
        assert_eq!(s.camera.depth_ray, DepthRay::Random);
        assert_eq!(s.estimator.depth_ray, RayAssumption::Centre);
        assert_eq!(s.targets.building_clearance_m, 3.0);
        for (bad, names) in [
            ("targets.speed_draw=\"per_minute\"", "per_car, per_step"),
            ("camera.depth_ray=\"corner\"", "centre, random"),
            ("estimator.depth_ray=\"random\"", "any, centre"),
        ] {
            let e = set(&[bad]).unwrap_err().to_string();
            assert!(e.contains(names), "{bad}: {e}");
        }
        let e = set(&["targets.building_clearance_m=2"])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("targets.safety_distance_m (3 m) <= value"),
            "{e}"
        );
    }

    #[test]
    fn the_planner_and_the_set_growth_are_one_of_their_names() {
        use super::super::Planner;
        assert_eq!(Scenario::default().guidance.planner, Planner::Paper);
        let s = Scenario::load(None, &["guidance.planner=setfleet".to_owned()]).unwrap();
        assert_eq!(s.guidance.planner, Planner::Setfleet);
        let s = Scenario::from_toml_str("[guidance]\nplanner = \"paper\"\n").unwrap();
        assert_eq!(s, Scenario::default());
        for bad in ["guidance.planner=magic", "guidance.planner=3"] {
            let e = Scenario::load(None, &[bad.to_owned()])
                .unwrap_err()
                .to_string();
            assert!(e.contains("guidance.planner"), "{bad}: {e}");
            assert!(e.contains("paper, setfleet"), "{bad}: {e}");
        }
        let s = Scenario::load(None, &["estimator.sets=geodesic".to_owned()]).unwrap();
        assert_eq!(s.estimator.sets, super::super::SetGrowth::Geodesic);
        let e = Scenario::load(None, &["estimator.sets=exact".to_owned()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("cells, reach, geodesic"), "{e}");
        // The resolved scenario writes the planner back as its name.
        assert!(
            Scenario::default()
                .to_toml_string()
                .contains("planner = \"paper\"")
        );
    }

    /// The keys choosing between readings of the paper take their names, default to the
    /// literal reading, write back as names, and refuse anything else naming the choices.
    #[test]
    fn the_readings_of_the_paper_are_one_of_their_names() {
        use super::super::{
            DistanceFrom, HiddenResolution, HiddenSets, HiddenWindow, PlanBorder, PredictedViews,
            SetResolution,
        };
        let g = Scenario::default().guidance;
        assert_eq!(g.hidden_resolution, HiddenResolution::Estimator);
        assert_eq!(g.hidden_window, HiddenWindow::Frames);
        assert_eq!(g.predicted_views, PredictedViews::PeriodEnd);
        assert_eq!(g.border, PlanBorder::Region);
        assert_eq!(g.set_resolution, SetResolution::Estimator);
        assert_eq!(g.distance_from, DistanceFrom::Uav);
        assert_eq!(g.hidden_sets, HiddenSets::Predicted);
        let other = [
            "guidance.hidden_resolution=planning",
            "guidance.hidden_window=periods",
            "guidance.predicted_views=every_frame",
            "guidance.border=geofence",
            "guidance.set_resolution=planning",
            "guidance.distance_from=view_centre",
            "guidance.hidden_sets=current",
        ]
        .map(str::to_owned);
        let s = Scenario::load(None, &other).unwrap();
        assert_eq!(s.guidance.hidden_resolution, HiddenResolution::Planning);
        assert_eq!(s.guidance.hidden_window, HiddenWindow::Periods);
        assert_eq!(s.guidance.predicted_views, PredictedViews::EveryFrame);
        assert_eq!(s.guidance.border, PlanBorder::Geofence);
        assert_eq!(s.guidance.set_resolution, SetResolution::Planning);
        assert_eq!(s.guidance.distance_from, DistanceFrom::ViewCentre);
        assert_eq!(s.guidance.hidden_sets, HiddenSets::Current);
        let text = s.to_toml_string();
        assert!(text.contains("predicted_views = \"every_frame\""), "{text}");
        assert!(text.contains("distance_from = \"view_centre\""), "{text}");
        assert_eq!(Scenario::from_toml_str(&text).unwrap(), s);
        for (bad, names) in [
            ("guidance.hidden_resolution=fine", "estimator, planning"),
            ("guidance.hidden_window=steps", "frames, periods"),
            ("guidance.predicted_views=all", "period_end, every_frame"),
            ("guidance.border=1", "region, geofence"),
            ("guidance.set_resolution=fine", "estimator, planning"),
            ("guidance.distance_from=camera", "uav, view_centre"),
            ("guidance.hidden_sets=both", "predicted, current"),
        ] {
            assert_refused_naming_the_choices(bad, names);
        }
        let s = Scenario::load(None, &["region.lot_size_m=40".to_owned()]).unwrap();
        assert_eq!(s.region.lot_size_m, 40.0);
        assert!(Scenario::load(None, &["region.lot_size_m=2".to_owned()]).is_err());
    }

    /// `bad` (`KEY=VALUE`) is refused with an error naming the key and every accepted name.
    fn assert_refused_naming_the_choices(bad: &str, names: &str) {
        let e = Scenario::load(None, &[bad.to_owned()])
            .unwrap_err()
            .to_string();
        let key = bad.split('=').next().unwrap();
        assert!(e.contains(key) && e.contains(names), "{bad}: {e}");
    }

    /// What the radio would not carry is a reading of its own: by default only what the radio
    /// carries reaches an agent; the earlier behaviour is one name away.
    #[test]
    fn the_readings_of_the_radio_are_one_of_their_names() {
        use super::super::{Liveness, TokenRange};
        let c = Scenario::default().comms;
        assert_eq!(
            (c.token_range, c.liveness),
            (TokenRange::Radio, Liveness::Radio)
        );
        let other = ["comms.token_range=unlimited", "comms.liveness=world"].map(str::to_owned);
        let s = Scenario::load(None, &other).unwrap();
        assert_eq!(s.comms.token_range, TokenRange::Unlimited);
        assert_eq!(s.comms.liveness, Liveness::World);
        let text = s.to_toml_string();
        assert!(text.contains("liveness = \"world\""), "{text}");
        assert_eq!(Scenario::from_toml_str(&text).unwrap(), s);
        for (bad, names) in [
            ("comms.token_range=ideal", "radio, unlimited"),
            ("comms.liveness=true", "radio, world"),
        ] {
            assert_refused_naming_the_choices(bad, names);
        }
    }

    #[test]
    fn the_largest_fleet_over_2_km_with_128_cars_is_accepted_and_one_more_uav_is_not() {
        let load = |uavs: u32| {
            Scenario::load(
                None,
                &[
                    format!("uavs.count={uavs}"),
                    "region.half_extent_m=1000".to_owned(),
                    "targets.count=128".to_owned(),
                ],
            )
        };
        let s = load(64).expect("64 UAVs, 128 cars");
        assert_eq!((s.uavs.count, s.targets.count), (64, 128));
        assert_eq!(MAX_UAVS, 64);
        assert_eq!(MAX_TARGETS, 128);
        let e = load(65).unwrap_err().to_string();
        assert!(
            e.contains("uavs.count") && e.contains("65") && e.contains("1 <= value <= 64"),
            "{e}"
        );
    }

    #[test]
    fn edge_values_inside_the_ranges_are_accepted() {
        let mut s = Scenario {
            seed: i64::MAX as u64,
            duration_s: MAX_DURATION_S,
            ..Scenario::default()
        };
        s.targets.count = 0;
        s.uavs.count = MAX_UAVS as u32;
        s.uavs.altitudes_m = (0..MAX_UAVS).map(|i| 61.0 + i as f64).collect();
        s.camera.unknown_fraction = 0.0;
        s.timing.guidance_period_s = 0.5;
        s.estimator.oem_cell_m = s.estimator.cell_m;
        s.guidance.yaw_increments_rad = vec![-PI, PI];
        s.guidance.horizon = 4;
        s.guidance.kappa = 0.0;
        s.comms.range_m = 1.0;
        s.comms.loss = 1.0;
        s.comms.latency_ms = MAX_LATENCY_MS;
        assert_eq!(s.validate().map_err(|e| e.to_string()), Ok(()));
        s.comms.loss = 0.0;
        s.comms.latency_ms = 0.0;
        assert_eq!(s.validate().map_err(|e| e.to_string()), Ok(()));
    }

    #[test]
    fn messages_explain_the_model_constraints() {
        let mut s = Scenario::default();
        s.targets.size_m = [6.0, 2.0, 1.5];
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("contains the car")
        );
        let mut s = Scenario::default();
        s.camera.tilt_rad = 0.2;
        assert!(
            s.validate()
                .unwrap_err()
                .to_string()
                .contains("below the horizon")
        );
    }
}
