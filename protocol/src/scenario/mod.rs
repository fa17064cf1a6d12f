//! The scenario: one TOML file, every key with the paper's value built in (docs/design.md §5).
//!
//! An empty file (or none) is the paper's scenario; a file names only what it changes:
//!
//! ```toml
//! seed = 7
//! duration_s = 120            # an integer is fine where a float is expected
//!
//! [uavs]
//! count = 3
//! altitudes_m = [80.0, 90.0, 100.0]
//!
//! [comms]
//! range_m = 150.0             # inf: perfect links
//! loss = 0.1                  # each message lost on a link with this probability
//! latency_ms = 250.0          # estimates fused this much later (whole CVS periods)
//! ```
//!
//! The `[comms]` keys and their ranges are tabled in [`CommsConfig`].
//!
//! Any key can be overridden as `KEY=VALUE`, the value written in TOML (`guidance.kappa=0`,
//! `uavs.altitudes_m=[80,90]`, `guidance.use_map=false`, `comms.range_m=inf`, `comms.loss=0.3`); overrides apply
//! in order, after the file:
//!
//! ```
//! use protocol::scenario::Scenario;
//!
//! let overrides = ["guidance.kappa=0".to_owned(), "comms.range_m=inf".to_owned()];
//! let scenario = Scenario::load(None, &overrides)?;
//! assert_eq!(scenario.guidance.kappa, 0.0);
//! assert_eq!(Scenario::from_toml_str(&scenario.to_toml_string())?, scenario);
//! # Ok::<(), protocol::scenario::ScenarioError>(())
//! ```
//!
//! Loading goes text -> TOML table -> overrides -> keys and types checked against the default
//! scenario's own table (so every error names the full dotted key, e.g. `guidance.kappa`) ->
//! serde -> [`Scenario::validate`] (every value against its range). Every failure is a
//! [`ScenarioError`] a user can act on.

use std::io;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use toml::{Table, Value};

use crate::camera::{Camera, CameraModel, CameraPose};
use sets::grid::GroundGrid;

mod overrides;
mod validate;

pub use validate::{MAX_LATENCY_MS, MAX_RELAY_HOPS};

/// Height above the tallest building of the lowest UAV when the scenario gives no altitudes, m.
pub const CLEARANCE_ABOVE_BUILDINGS_M: f64 = 20.0;
/// Default of `uavs.altitude_step_m`: the altitude step between consecutive UAVs when the
/// scenario gives no altitudes, m.
pub const ALTITUDE_STEP_M: f64 = 10.0;

use overrides::Override;

/// Why a scenario could not be read, parsed or accepted.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The scenario file could not be read (missing, unreadable, not UTF-8).
    #[error("cannot read the scenario file {}: {source}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        source: io::Error,
    },
    /// The text is not valid TOML.
    #[error("{origin}:{line}:{column}: invalid TOML: {message}")]
    Syntax {
        /// Where the text came from: the file's path, or `<string>`.
        origin: String,
        /// Line of the error, from 1.
        line: usize,
        /// Column of the error in characters, from 1.
        column: usize,
        /// What the TOML parser expected.
        message: String,
    },
    /// A key the scenario does not have (often a typo).
    #[error("unknown key `{key}`; {}", list_keys(key, expected))]
    UnknownKey {
        /// The full dotted key, e.g. `guidance.kapa`.
        key: String,
        /// The valid keys at that level, sorted.
        expected: Vec<String>,
    },
    /// A value of the wrong kind, e.g. a string where a number belongs.
    #[error("`{key}` must be {expected}, found {found}")]
    WrongType {
        /// The full dotted key.
        key: String,
        /// The kind the key takes, e.g. "a number (float or integer)".
        expected: String,
        /// The kind found, with the value when short, e.g. `string "fast"`.
        found: String,
    },
    /// A value outside the key's accepted range.
    #[error("`{key}` = {value} is out of range; accepted: {accepted}")]
    OutOfRange {
        /// The full dotted key.
        key: String,
        /// The value given.
        value: String,
        /// The accepted range as text, e.g. "0 < value <= 100".
        accepted: String,
    },
    /// An override not of the form `KEY=VALUE` with a dotted key and a TOML value.
    #[error(
        "bad override `{text}`: {reason} (expected KEY=VALUE with a TOML value, \
         e.g. guidance.kappa=0 or uavs.altitudes_m=[80,90])"
    )]
    BadOverride {
        /// The override as given.
        text: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The table passed the key and type checks, yet serde refused it: the schema walk and the
    /// [`Scenario`] struct disagree, which is a bug in setfleet, not in the scenario.
    #[error("internal scenario schema error (a bug in setfleet, please report it): {message}")]
    Schema {
        /// What serde said.
        message: String,
    },
}

/// "the top-level keys are: a, b" or "the keys of [guidance] are: ...".
fn list_keys(key: &str, expected: &[String]) -> String {
    let keys = expected.join(", ");
    match key.rsplit_once('.') {
        Some((parent, _)) if expected.is_empty() => format!("`{parent}` holds no keys"),
        Some((parent, _)) => format!("the keys of [{parent}] are: {keys}"),
        None => format!("the top-level keys are: {keys}"),
    }
}

/// The whole scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    /// Seed of every random choice of the run.
    pub seed: u64,
    /// Simulated duration, seconds.
    pub duration_s: f64,
    /// The city.
    pub region: RegionConfig,
    /// An imported city, instead of the generated one.
    pub city: CityConfig,
    /// The cars.
    pub targets: TargetsConfig,
    /// The fleet.
    pub uavs: UavsConfig,
    /// The camera and its vision system.
    pub camera: CameraConfig,
    /// Periods.
    pub timing: TimingConfig,
    /// Set resolution.
    pub estimator: EstimatorConfig,
    /// The MPC.
    pub guidance: GuidanceConfig,
    /// Links between UAVs.
    pub comms: CommsConfig,
}

/// `[region]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegionConfig {
    /// The RoI is `[-h, h]^2`.
    pub half_extent_m: f64,
    /// Share of the ground under buildings, `0 <= value <= 0.3` (the paper's city: about
    /// 0.05). The world also refuses a share its city blocks cannot hold.
    pub building_fraction: f64,
    /// Range of building heights `[lo, hi]`.
    pub building_height_m: [f64; 2],
    /// Side the city's building lots aim for, metres (`4 <= value <= 200`): each block of
    /// the road grid is cut into lots of about this side, at most one building per lot, each
    /// building 45 % to 100 % of its lot's sides. The paper shows its city, not its lots.
    pub lot_size_m: f64,
}

/// `[city]`: an imported city (`fleet city` writes it) in place of the one generated from
/// the seed. With a scene, the world takes its buildings and roads from the scene file, and
/// `[region]` keeps only `half_extent_m` (which must be the scene's) and `building_height_m`
/// (the roofs' range, for the pictures' colours and the fleet's nominal altitude).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CityConfig {
    /// The scene file (`city.json`); empty: the generated city. A relative path is taken from
    /// the folder of the scenario file that names it ([`Scenario::load`] makes it absolute).
    pub scene: String,
    /// Height of a storey, for buildings mapped with `building:levels` and no `height`,
    /// metres (`1 <= value <= 10`).
    pub storey_height_m: f64,
    /// Height of a building mapped with neither, metres (`1 <= value <= 500`).
    pub default_height_m: f64,
    /// Who drives the cars of an imported city ([`CityTraffic`]; `"roads"`, the default: the
    /// world's own model).
    pub traffic: CityTraffic,
    /// The trace file of `traffic = "trace"` (CSV: `time_s,car,x_m,y_m,heading_rad`). A
    /// relative path is taken from the scenario file's folder, as `scene` is.
    pub trace: String,
}

/// Who drives the cars of an imported city (`city.traffic`). Whichever it is, the world checks
/// every car's every step: at most `v_max T` long, and `targets.building_clearance_m` from
/// every building, inside the region.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CityTraffic {
    /// The world's own model on the scene's roads (both ways on every road).
    #[default]
    Roads,
    /// SUMO, run ahead of the world from the seed on the scene's roads (one-way streets kept).
    Sumo,
    /// A recorded trace, `city.trace`.
    Trace,
}

impl CityTraffic {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 3] = ["roads", "sumo", "trace"];
}

/// `[targets]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TargetsConfig {
    /// Number of cars.
    pub count: u32,
    /// `v_max`, m/s.
    pub max_speed_mps: f64,
    /// Car length, width, height.
    pub size_m: [f64; 3],
    /// Target model radius `r_t`.
    pub radius_m: f64,
    /// Target model height `h_t`.
    pub cylinder_height_m: f64,
    /// Safety distance `r_s` from obstacles and other targets.
    pub safety_distance_m: f64,
    /// Spread of the cars' cruise speeds: each car cruises at `v_max (1 - spread u)`, `u`
    /// uniform in `[0, 1)` (the paper does not say how its speeds are drawn; 0: every car at
    /// `v_max`).
    pub cruise_spread: f64,
    /// The smallest distance the world keeps between a car's centre and every building, m
    /// (`>= r_s`). The paper asks only for "a distance larger than `r_s`"; the default,
    /// 6 m, is `r_s + r_t` plus a 0.5 m margin for the default cars, which keeps the whole
    /// target cylinder clear of the walls. `r_s` lets cars come as close as the paper allows.
    pub building_clearance_m: f64,
    /// When a car's cruise speed is drawn: `"per_car"` (the default, once per run) or
    /// `"per_step"` (again at every CVS period) ([`SpeedDraw`]).
    pub speed_draw: SpeedDraw,
    /// Stops a car starts per minute it is not stopped, on average (`0 <= value <= 60`; 0,
    /// the default: no stops). At each CVS period a car not already stopped stops with
    /// probability `stops_per_min * T / 60` and stands still for a time uniform in `stop_s`.
    pub stops_per_min: f64,
    /// Range `[lo, hi]` of a stop's length, seconds (`0 <= lo <= hi <= 600`).
    pub stop_s: [f64; 2],
}

/// When each car's cruise speed `v_max (1 - cruise_spread u)`, `u` uniform in `[0, 1)`, is
/// drawn (`targets.speed_draw`). The paper says only that the speeds are "randomly chosen but
/// bounded"; every choice keeps a car's displacement per period within `v_max T`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SpeedDraw {
    /// Once per car, at placement: the car cruises at that speed for the whole run.
    #[default]
    PerCar,
    /// Again at every CVS period, for every car.
    PerStep,
}

impl SpeedDraw {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["per_car", "per_step"];
}

/// `[uavs]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UavsConfig {
    /// Number of UAVs.
    pub count: u32,
    /// Constant ground speed, m/s.
    pub speed_mps: f64,
    /// Altitudes; empty for distinct altitudes above every building, `altitude_step_m` apart.
    pub altitudes_m: Vec<f64>,
    /// Altitude step between consecutive UAVs when `altitudes_m` is empty, m (> 0). A camera
    /// higher up sees more ground, so a large fleet on automatic altitudes gets a smaller
    /// step to keep its band (`fleet bench scale` does).
    pub altitude_step_m: f64,
    /// Largest yaw rate, rad/s.
    pub max_yaw_rate_rps: f64,
}

/// `[camera]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    /// Image rows.
    pub rows: u32,
    /// Image columns.
    pub cols: u32,
    /// Horizontal aperture, radians.
    pub aperture_rad: f64,
    /// Tilt below the horizon, radians.
    pub tilt_rad: f64,
    /// Multiplicative depth noise bounds `[w_lo, w_hi]`.
    pub depth_noise: [f64; 2],
    /// Share of pixels labelled unknown at random.
    pub unknown_fraction: f64,
    /// Visible pixels needed to identify a target.
    pub min_pixels: u32,
    /// Which ray of a pixel its depth is measured along (`"centre"` or `"random"`,
    /// [`DepthRay`]).
    pub depth_ray: DepthRay,
}

/// The ray of a pixel along which the world measures its depth (`camera.depth_ray`). The
/// paper's eq. (5) says only that the depth is the range along some ray of the pixel; the
/// estimator's default rule assumes no more ([`RayAssumption::Any`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DepthRay {
    /// The ray through the pixel's centre.
    #[default]
    Centre,
    /// A ray through a point drawn uniformly in the pixel, per pixel and frame from the
    /// scenario's seed (another simulator or a real depth camera, which measure along no
    /// particular ray).
    Random,
}

impl DepthRay {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["centre", "random"];
}

/// `[timing]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TimingConfig {
    /// CVS and estimation period `T`, seconds.
    pub cvs_period_s: f64,
    /// Guidance period, seconds (a whole number of CVS periods).
    pub guidance_period_s: f64,
    /// Longest wait of an agent for an external planner's answer, milliseconds (1 to 60000;
    /// docs/python.md): a later answer is not waited for and the fallback planner decides.
    pub external_planner_ms: u32,
}

/// `[estimator]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorConfig {
    /// Bit-raster cell side, metres.
    pub cell_m: f64,
    /// OEM cell side, metres.
    pub oem_cell_m: f64,
    /// How the sets grow between observations: `"reach"` (the default), `"geodesic"` or
    /// `"cells"` ([`SetGrowth`]).
    pub sets: SetGrowth,
    /// What the estimator assumes of the ray a depth was measured along: `"any"` (the
    /// default, the paper's eq. 5) or `"centre"` ([`RayAssumption`]).
    pub depth_ray: RayAssumption,
    /// Half-side, metres, of the square around its UAV over which an agent keeps the reach
    /// of `X̄`, with a lower bound per block of cells outside it (docs/design.md §3, "Agent
    /// windows"). `inf`, the default, keeps it over the whole region, as the design's
    /// estimator does; a large fleet sets it to what its guidance reads, so that an agent's
    /// work and memory follow its neighbourhood rather than the fleet.
    pub window_m: f64,
}

/// What the estimator assumes of the ray along which a pixel's depth was measured
/// (`estimator.depth_ray`). Only `S^o` and the map read a depth's direction: `P^g` reads no
/// depth, and `X^m_j` always takes the whole pixel's frustum.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RayAssumption {
    /// Some unknown ray of the pixel (the paper's eq. 5): an obstacle pixel proves an
    /// obstacle point somewhere in its depth frustum. Sound for any depth source.
    #[default]
    Any,
    /// The pixel's centre ray: an obstacle point on that ray. Tighter, by up to half a
    /// pixel's footprint, and sound **only** for a source that measures along the centre ray
    /// (this project's renderer with `camera.depth_ray = "centre"`); fed any other depth it
    /// can put `S^o` over a car.
    Centre,
}

impl RayAssumption {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["any", "centre"];
}

/// How the estimator's sets grow between observations (`estimator.sets`); every choice keeps
/// the guarantee, they differ in how tight the sets stay.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SetGrowth {
    /// Whole-cell dilation by the motion at every step, the rasters of the paper: the growth
    /// is rounded out to whole cells at every step.
    Cells,
    /// Each cell remembers how far the set's targets are from it, so sets grow by exactly the
    /// motion (`sets::raster::reach`).
    #[default]
    Reach,
    /// As `reach`, and the distances go around the ground proven to be within `r_s` of an
    /// obstacle, which no car can cross (`sets::raster::geodesic`).
    Geodesic,
}

impl SetGrowth {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 3] = ["cells", "reach", "geodesic"];
}

/// `[guidance]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GuidanceConfig {
    /// Prediction horizon `h`, guidance periods.
    pub horizon: u32,
    /// The yaw increments `U`, radians.
    pub yaw_increments_rad: Vec<f64>,
    /// Weight `λ` of the distance term.
    pub lambda: f64,
    /// Weight `κ` of the previously-occluded term.
    pub kappa: f64,
    /// Whether the MPC uses the OEM.
    pub use_map: bool,
    /// Which planner decides: `"paper"` (the paper's MPC, the default), `"setfleet"` (the
    /// project's beam search) or `"external"` (every UAV asks an external planner and falls
    /// back to the paper's MPC; docs/python.md). The keys of [`SetfleetConfig`] are read by
    /// `setfleet` only.
    pub planner: Planner,
    /// The UAVs that ask an external planner for their decisions (docs/python.md), falling
    /// back to `planner`; the others decide with `planner` (`fleet run --planner
    /// external:0,2`). Default: none.
    pub external_uavs: Vec<u32>,
    /// When an asking UAV sends its request: `"turn"` (the default: in its turn of the token
    /// ring, with the plans of the UAVs ahead) or `"round_start"` ([`ExternalRequest`]).
    pub external_request: ExternalRequest,
    /// The `setfleet` planner's keys, written in `[guidance]` itself.
    #[serde(flatten)]
    pub setfleet: SetfleetConfig,
    /// The paper's MPC: how `Φ_h` measures the predicted sets inside recently hidden ground:
    /// `"estimator"` (the default) or `"planning"` ([`HiddenResolution`]).
    pub hidden_resolution: HiddenResolution,
    /// What "the last `h` time steps" of the paper's eq. (28) counts, for every planner's
    /// recently hidden ground: `"frames"` (the default) or `"periods"` ([`HiddenWindow`]).
    pub hidden_window: HiddenWindow,
    /// The paper's MPC: which predicted poses' fields of view it removes from the predicted
    /// sets: `"period_end"` (the default) or `"every_frame"` ([`PredictedViews`]).
    pub predicted_views: PredictedViews,
    /// The square every planner keeps its plans in: `"region"` (the default) or
    /// `"geofence"` ([`PlanBorder`]).
    pub border: PlanBorder,
    /// The paper's MPC: the grid it predicts its sets on, and so measures `Φ_X` and `Φ_d` on:
    /// `"estimator"` (the default) or `"planning"` ([`SetResolution`]).
    pub set_resolution: SetResolution,
    /// The paper's MPC: the point `Φ_d` is measured from: `"uav"` (the default) or
    /// `"view_centre"` ([`DistanceFrom`]).
    pub distance_from: DistanceFrom,
    /// The paper's MPC: which sets `Φ_h` counts inside recently hidden ground: `"predicted"`
    /// (the default) or `"current"` ([`HiddenSets`]).
    pub hidden_sets: HiddenSets,
}

/// The `setfleet` planner's keys of `[guidance]` (flattened into it: a scenario writes
/// `guidance.beam_width`, not a table of its own). The planner reads them as they are
/// (`uav_agent::guidance::setfleet`), `spread_m` and `track_revisit_s` scaled where it uses them
/// when `adapt_weights` is set (`uav_agent::guidance::weights`). The paper's MPC reads none.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SetfleetConfig {
    /// Guidance periods looked ahead by the beam search.
    pub lookahead_periods: u32,
    /// Partial sequences kept after each period of the beam search.
    pub beam_width: u32,
    /// Weight of the identified targets' set area against `X̄`'s (per m²).
    pub target_weight: f64,
    /// Seconds of future growth charged on every set left unobserved: a set is valued by its
    /// area grown by `max_speed_mps` times this (0: only today's area counts).
    pub growth_horizon_s: f64,
    /// Distance between view centres below which this UAV's plan is charged for overlapping
    /// the plans already in the token, metres (0: no charge).
    pub spread_m: f64,
    /// How the fleet shares the search: `"none"` (the default: every UAV values all ground
    /// alike), `"sectors"` (a lane each) or `"lanes"` (lanes of one front) ([`SweepPlan`]).
    pub sweep: SweepPlan,
    /// The revisit period of the tracking schedule, seconds: an identified car whose set has
    /// grown past the area its targets' speed covers in this time (a disc of radius
    /// `max_speed_mps * track_revisit_s`) is revisited first by the UAV whose lane holds it
    /// (0: no schedule).
    pub track_revisit_s: f64,
    /// Whether a UAV plans a second viewpoint for the largest pocket of `X̄` hidden from where
    /// the UAVs flew in its own ground, and flies there when worth the detour
    /// (`uav_agent::guidance::viewpoint`).
    pub second_viewpoints: bool,
    /// Whether `lambda`, `spread_m` and `track_revisit_s` are those of the default scenario,
    /// scaled to this one by the camera footprint's width and the targets' speed
    /// (`uav_agent::guidance::weights`), instead of taken as they are.
    pub adapt_weights: bool,
}

/// How the MPC's `Φ_h` measures the predicted sets inside recently hidden ground
/// (`guidance.hidden_resolution`). The choices differ in what a coarse planning cell
/// (`uav_agent::guidance::coarse`) counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HiddenResolution {
    /// Estimator cells that lie both in the sets (those `guidance.hidden_sets` names) and in
    /// the hidden ground are counted: the overlap is measured at the estimator's resolution,
    /// and a coarse cell can never count an overlap its fine cells do not have. With the
    /// sets predicted on planning cells (`guidance.set_resolution = "planning"`), each
    /// predicted planning cell counts its estimator cells in the overlap.
    #[default]
    Estimator,
    /// A predicted planning cell counts whole when any of its estimator cells is hidden (the
    /// any-cell coarsening of both sets, which can count a set cell and a hidden cell that
    /// only share a coarse cell).
    Planning,
}

impl HiddenResolution {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["estimator", "planning"];
}

/// What "the `H^CVS` obtained during the last `h` time steps" (the paper's eq. 28) counts
/// (`guidance.hidden_window`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HiddenWindow {
    /// The last `h` CVS frames (the paper's time index `k` is the CVS step).
    #[default]
    Frames,
    /// Every frame of the last `h` guidance periods, the current one included.
    Periods,
}

impl HiddenWindow {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["frames", "periods"];
}

/// Which predicted fields of view the MPC removes from its predicted sets
/// (`guidance.predicted_views`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PredictedViews {
    /// `F^P_{k+τ}` only, the pose at the end of each of the `h` guidance periods (the
    /// paper's eqs. 29-30).
    #[default]
    PeriodEnd,
    /// The pose of every CVS frame of each period (the camera sees at every frame).
    EveryFrame,
}

impl PredictedViews {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["period_end", "every_frame"];
}

/// The square the MPC keeps its plans in (`guidance.border`): sequences whose predicted
/// positions leave it are excluded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlanBorder {
    /// The RoI, as the paper writes (sequences that would leave the RoI are excluded): plans
    /// between the world's geofence and the RoI's edge are overridden by the world's turn back
    /// to the centre.
    #[default]
    Region,
    /// The world's geofence ([`Scenario::geofence_half_extent`]), inside which the world
    /// never overrides a command: a plan the MPC keeps is a plan the UAV flies, but the outer
    /// band of the RoI (26 m by default) is never planned over.
    Geofence,
}

impl PlanBorder {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["region", "geofence"];
}

/// The grid the paper's MPC predicts its sets on (`guidance.set_resolution`), and so the
/// resolution of `Φ_X`, `Φ_d` and `Φ_h`'s sets (`uav_agent::guidance::paper`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SetResolution {
    /// The estimator's grid (0.5 m cells by default): the sets as the estimator holds them,
    /// dilated and cleared by the predicted views cell by cell; `Φ_X` counts their cells and
    /// `Φ_d` reaches the nearest of them.
    #[default]
    Estimator,
    /// The coarse planning grid (2.5 m cells by default): a planning cell is in the sets when
    /// any of its estimator cells is, and counts whole.
    Planning,
}

impl SetResolution {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["estimator", "planning"];
}

/// The point the paper's MPC measures `Φ_d` from (`guidance.distance_from`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DistanceFrom {
    /// `p_g(x^u_{k+h})`, the UAV's predicted ground position at the end of the horizon (the
    /// paper's definition of `Φ_d`).
    #[default]
    Uav,
    /// The ground point the camera's optical axis meets from the predicted final pose.
    ViewCentre,
}

impl DistanceFrom {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["uav", "view_centre"];
}

/// Which sets the paper's MPC counts inside recently hidden ground for `Φ_h`
/// (`guidance.hidden_sets`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HiddenSets {
    /// The predicted sets at the end of the horizon, `X̄^P_{k+h} ∪ X^P_{j,k+h}` (the paper's
    /// definition of `Φ_h`, with eq. 28's hidden ground).
    #[default]
    Predicted,
    /// Today's sets, counted where the predicted sets still hold them. With
    /// `hidden_resolution = "planning"` this is the same as `Predicted`: the any-cell
    /// coarsening of the hidden ground is counted on the predicted cells.
    Current,
}

impl HiddenSets {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["predicted", "current"];
}

/// How the `setfleet` planner shares the search among the fleet (`guidance.sweep`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SweepPlan {
    /// Every UAV values all ground alike; the token only spreads the plans.
    #[default]
    None,
    /// A lane each: the round's fleet splits the region into one lane per UAV, whose ground
    /// the UAV values most (`uav_agent::guidance::sweep`).
    Sectors,
    /// Lanes of one front: the round's fleet splits the region into one lane per UAV, each
    /// cleared from its south edge northwards, ground behind the front first
    /// (`uav_agent::guidance::sweep`).
    Lanes,
}

impl SweepPlan {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 3] = ["none", "sectors", "lanes"];
}

/// The guidance planner (`guidance.planner`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Planner {
    /// The paper's MPC, exhaustive over `U^h` (docs/design.md §4).
    #[default]
    Paper,
    /// The project's planner: beam search over longer sequences, with the future growth of
    /// unobserved sets in its cost.
    Setfleet,
    /// Every UAV asks an external planner (docs/python.md); the paper's MPC decides when no
    /// answer comes in time.
    External,
}

impl Planner {
    /// Every planner's name, as written in a scenario.
    pub const NAMES: [&'static str; 3] = ["paper", "setfleet", "external"];
}

/// When a UAV that asks an external planner sends its request (`guidance.external_request`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExternalRequest {
    /// In its turn of the token ring, with the plans of the UAVs ahead.
    #[default]
    Turn,
    /// At the start of the round, before the token comes, without the plans ahead: the
    /// requests of a round's asking UAVs all exist before any of them is answered (what a
    /// multi-agent environment that steps its UAVs together needs).
    RoundStart,
}

impl ExternalRequest {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["turn", "round_start"];
}

/// `[comms]`: the simulated radio links between agents. Every message still crosses the IPC
/// (or the bridge); the receiving agent decides, by the same rules the observer applies, whether
/// the radio carried it ([`crate::radio`]).
///
/// | key | default | accepted | meaning |
/// |---|---|---|---|
/// | `range_m` | `inf` | `0 < value <= inf` | an estimate is fused only when the sender's camera (as it sent) is within this horizontal distance of the receiver's (as it fuses) |
/// | `loss` | `0.0` | `0 <= value <= 1` | probability that the radio loses one message on one link (estimates and tokens alike), drawn from `seed`, the kind of message, the sender, the receiver and the step: the same seed loses the same messages |
/// | `latency_ms` | `0.0` | `0 <= value <= 10000` | an estimate of step `k` is fused at the receiver's first step whose time is at least `t(k) + latency`, `ceil(latency / cvs_period_s)` steps later, dilated by that lag; tokens are not delayed (the ring's hops take no simulated time, like the planners' computing) |
/// | `token_range` | `"radio"` | `"radio"`, `"unlimited"` | whether `range_m` limits the guidance token as it limits estimates ([`TokenRange`]) |
/// | `liveness` | `"radio"` | `"radio"`, `"world"` | where an agent learns which UAVs are live, for the token ring and the round's fleet ([`Liveness`]) |
/// | `exchange` | `"measurements"` | `"sets"`, `"measurements"` | what estimates carry ([`Exchange`]) |
/// | `whole_sets_every` | `20` | `1 <= value <= 10000` | under `exchange = "measurements"` with some `loss` or a finite `range_m`, an estimate also carries the sender's whole sets every this many messages, which relay what a lost message or the range kept from a receiver; on any links, whole sets also go in an agent's first message, after a peer joined late or restarted, and to a peer that missed a message |
/// | `relay_hops` | `0` | `0 <= value <= 8` | under `exchange = "measurements"`, an agent forwards in its next estimate every peer measurement it applied that has been forwarded fewer than this many times, so a measurement reaches UAVs up to this many hops beyond the radio's range, a step later per hop (0: no forwarding) |
///
/// With the defaults (`range_m = inf`, no loss) every message reaches every agent, and the two
/// readings of `token_range` and of `liveness` give the same runs, bit for bit, as long as no
/// agent dies, stalls or misses a wait.
///
/// `latency_ms` is bounded because every receiver, and the observer, holds the estimates in
/// flight: 10 s is 20 steps of the default scenario's estimates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommsConfig {
    /// Link range, metres; infinite for perfect links.
    pub range_m: f64,
    /// Probability that a message is lost on one link, in `[0, 1]`.
    pub loss: f64,
    /// Delay of an estimate on a link, milliseconds (rounded up to whole CVS periods).
    pub latency_ms: f64,
    /// Whether the radio's range limits the guidance token.
    pub token_range: TokenRange,
    /// Where an agent learns which UAVs are live.
    pub liveness: Liveness,
    /// What estimates carry.
    pub exchange: Exchange,
    /// Under the measurement exchange, steps between two estimates with whole sets.
    pub whole_sets_every: u32,
    /// Under the measurement exchange, how many times a peer measurement is forwarded.
    pub relay_hops: u32,
}

/// Whether the radio's range (`comms.range_m`) limits the guidance token (`comms.token_range`).
/// Loss (`comms.loss`) drops tokens under either reading.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TokenRange {
    /// A token reaches an agent only from a sender within range of it, as an estimate does
    /// (the sender's camera as it sent, the receiver's at the same step): a token out of range
    /// is lost to that receiver (`protocol::radio::Radio::carries_token`).
    #[default]
    Radio,
    /// Every token reaches every agent whatever the range (the behaviour before the key): the
    /// plans of UAVs out of range still reach the agents, which no radio would carry.
    Unlimited,
}

impl TokenRange {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["radio", "unlimited"];
}

/// Where an agent learns which UAVs are live (`comms.liveness`): whom the token ring waits
/// for and skips, and which UAVs share the `setfleet` sweep's lanes (the round's fleet).
/// Under either reading an agent's waits for the peers' messages of a step end when the
/// world's frame says a peer is not served or the run's node list says it is dead: those only
/// say that a message will never be sent, not what a message would have said.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Liveness {
    /// From the messages the radio carried to it: at its step, an agent knows live exactly
    /// the peers whose estimate it fuses then (delivered, arrived, sent from within range),
    /// so a UAV out of range or whose estimate was lost is not waited for; each agent has its
    /// own view (`uav_agent::guidance::ring`).
    #[default]
    Radio,
    /// From the world: the frame's mask of the UAVs it serves, the same for every agent, and
    /// the run's node list (the behaviour before the key).
    World,
}

impl Liveness {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["radio", "world"];
}

/// What the agents' estimates carry (`comms.exchange`); both keep the guarantee.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Exchange {
    /// The sender's sets after correction, fused by intersection (the paper's exchange):
    /// they hold what the whole fleet saw, so their size and their fusion grow with the fleet.
    Sets,
    /// What the sender's frame proved (free ground, hidden ground, new obstacle ground, the
    /// cars' measurements), applied by each receiver as its own correction; whole sets only
    /// every `whole_sets_every` steps and for a peer that (re)joined. The size of a message
    /// and the work of applying it follow one camera window, not the fleet. The default: a
    /// 30-seed paired sweep found no loss of search quality against `Sets`.
    #[default]
    Measurements,
}

impl Exchange {
    /// Every choice's name, as written in a scenario.
    pub const NAMES: [&'static str; 2] = ["sets", "measurements"];

    /// The choice's name, as written in a scenario (one of [`Exchange::NAMES`]).
    pub fn name(self) -> &'static str {
        match self {
            Exchange::Sets => "sets",
            Exchange::Measurements => "measurements",
        }
    }
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            seed: 1,
            duration_s: 300.0,
            region: RegionConfig::default(),
            city: CityConfig::default(),
            targets: TargetsConfig::default(),
            uavs: UavsConfig::default(),
            camera: CameraConfig::default(),
            timing: TimingConfig::default(),
            estimator: EstimatorConfig::default(),
            guidance: GuidanceConfig::default(),
            comms: CommsConfig::default(),
        }
    }
}

impl Default for RegionConfig {
    fn default() -> Self {
        Self {
            half_extent_m: 250.0,
            building_fraction: 0.05,
            building_height_m: [10.0, 60.0],
            lot_size_m: 21.0,
        }
    }
}

impl Default for CityConfig {
    fn default() -> Self {
        Self {
            scene: String::new(),
            storey_height_m: 3.0,
            default_height_m: 12.0,
            traffic: CityTraffic::Roads,
            trace: String::new(),
        }
    }
}

impl Default for TargetsConfig {
    fn default() -> Self {
        Self {
            count: 8,
            max_speed_mps: 2.0,
            size_m: [4.6, 1.8, 1.5],
            radius_m: 2.5,
            cylinder_height_m: 2.0,
            safety_distance_m: 3.0,
            cruise_spread: 0.8,
            building_clearance_m: 6.0,
            speed_draw: SpeedDraw::PerCar,
            stops_per_min: 0.0,
            stop_s: [5.0, 30.0],
        }
    }
}

impl Default for UavsConfig {
    fn default() -> Self {
        Self {
            count: 4,
            speed_mps: 10.0,
            altitudes_m: Vec::new(),
            altitude_step_m: ALTITUDE_STEP_M,
            max_yaw_rate_rps: 1.0,
        }
    }
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            rows: 360,
            cols: 480,
            aperture_rad: std::f64::consts::FRAC_PI_4,
            tilt_rad: std::f64::consts::FRAC_PI_4,
            depth_noise: [-0.01, 0.01],
            unknown_fraction: 0.0,
            min_pixels: 20,
            depth_ray: DepthRay::Centre,
        }
    }
}

impl Default for TimingConfig {
    fn default() -> Self {
        Self {
            cvs_period_s: 0.5,
            guidance_period_s: 3.0,
            external_planner_ms: 1000,
        }
    }
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            cell_m: 0.5,
            oem_cell_m: 5.0,
            sets: SetGrowth::Reach,
            depth_ray: RayAssumption::Any,
            window_m: f64::INFINITY,
        }
    }
}

impl Default for GuidanceConfig {
    fn default() -> Self {
        use std::f64::consts::PI;
        Self {
            horizon: 2,
            // `PI / 3.0`, not `FRAC_PI_3` (one ulp apart): these are the very numbers docs/design.md
            // §5 writes, so its example file is exactly the default.
            yaw_increments_rad: vec![-PI / 3.0, -PI / 6.0, 0.0, PI / 6.0, PI / 3.0],
            lambda: 1e-5,
            kappa: 1.0,
            use_map: true,
            planner: Planner::Paper,
            external_uavs: Vec::new(),
            external_request: ExternalRequest::Turn,
            setfleet: SetfleetConfig::default(),
            hidden_resolution: HiddenResolution::Estimator,
            hidden_window: HiddenWindow::Frames,
            predicted_views: PredictedViews::PeriodEnd,
            border: PlanBorder::Region,
            set_resolution: SetResolution::Estimator,
            distance_from: DistanceFrom::Uav,
            hidden_sets: HiddenSets::Predicted,
        }
    }
}

impl Default for SetfleetConfig {
    fn default() -> Self {
        Self {
            lookahead_periods: 6,
            beam_width: 4,
            target_weight: 4.0,
            growth_horizon_s: 10.0,
            spread_m: 60.0,
            sweep: SweepPlan::None,
            track_revisit_s: 0.0,
            second_viewpoints: false,
            adapt_weights: false,
        }
    }
}

impl Default for CommsConfig {
    fn default() -> Self {
        Self {
            range_m: f64::INFINITY,
            loss: 0.0,
            latency_ms: 0.0,
            token_range: TokenRange::Radio,
            liveness: Liveness::Radio,
            exchange: Exchange::Measurements,
            whole_sets_every: 20,
            relay_hops: 0,
        }
    }
}

impl Scenario {
    /// The camera model of the scenario.
    pub fn camera_model(&self) -> CameraModel {
        CameraModel {
            rows: self.camera.rows,
            cols: self.camera.cols,
            aperture_rad: self.camera.aperture_rad,
            tilt_rad: self.camera.tilt_rad,
        }
    }

    /// The bit-raster grid of the scenario.
    pub fn grid(&self) -> GroundGrid {
        GroundGrid::new(self.region.half_extent_m, self.estimator.cell_m)
    }

    /// The OEM grid of the scenario.
    pub fn oem_grid(&self) -> GroundGrid {
        GroundGrid::new(self.region.half_extent_m, self.estimator.oem_cell_m)
    }

    /// Number of steps of the run: `duration_s / cvs_period_s`, rounded.
    pub fn steps(&self) -> u64 {
        (self.duration_s / self.timing.cvs_period_s).round() as u64
    }

    /// Half side of the world's geofence square `[-f, f]^2`: the RoI shrunk by two turn
    /// radii, a step's travel and a metre, but never below half the RoI. The world turns a UAV
    /// back toward the centre when its command would take it out of the fence within a step,
    /// and a UAV turning back at its largest rate from the fence never leaves the RoI; the
    /// MPC keeps its plans inside the same square when `guidance.border = "geofence"`.
    pub fn geofence_half_extent(&self) -> f64 {
        let h = self.region.half_extent_m;
        let v = self.uavs.speed_mps;
        let w = self.uavs.max_yaw_rate_rps;
        let buffer = if w > 0.0 {
            2.0 * v / w + v * self.timing.cvs_period_s + 1.0
        } else {
            f64::INFINITY
        };
        (h - buffer).max(0.5 * h)
    }

    /// Altitude of UAV `i` at launch: `uavs.altitudes_m[i]`, or, when the scenario gives
    /// none, [`CLEARANCE_ABOVE_BUILDINGS_M`] above the tallest building of the city plus
    /// `uavs.altitude_step_m` per UAV before it.
    pub fn uav_altitude(&self, i: usize, tallest_building: f64) -> f64 {
        match self.uavs.altitudes_m.get(i) {
            Some(&z) => z,
            None => {
                tallest_building
                    + CLEARANCE_ABOVE_BUILDINGS_M
                    + self.uavs.altitude_step_m * i as f64
            }
        }
    }

    /// The fleet's mean altitude before the city is drawn: [`Scenario::uav_altitude`] with the
    /// tallest building at the top of `region.building_height_m` (what a planner can know from
    /// the scenario alone).
    pub fn nominal_altitude(&self) -> f64 {
        let n = self.uavs.count.max(1) as usize;
        let tallest = self.region.building_height_m[1];
        (0..n).map(|i| self.uav_altitude(i, tallest)).sum::<f64>() / n as f64
    }

    /// How far from its UAV's ground point an agent's guidance reads `X̄` closely, metres:
    /// the ground one guidance plan can look at. A plan moves the UAV `speed_mps x
    /// guidance_period_s` per period for `horizon` periods and is made a period before it
    /// starts (so `horizon + 1` periods of travel), and from each pose the camera sees ground
    /// as far as the farthest corner of its image's footprint on flat ground, taken at the
    /// fleet's highest altitude ([`Scenario::uav_altitude`] with the tallest building of
    /// `region.building_height_m`). Rounded up to whole 10 m. It is the window `fleet bench
    /// scale --window-m auto` gives every agent (`estimator.window_m`, docs/design.md §3):
    /// inside it the planner's footprints read the same `X̄` as without a window.
    /// `inf` if a corner of the image looks at or above the horizon.
    pub fn guidance_reach_m(&self) -> f64 {
        let travel = self.uavs.speed_mps
            * self.timing.guidance_period_s
            * f64::from(self.guidance.horizon + 1);
        let tallest = self.region.building_height_m[1];
        let highest = (0..self.uavs.count.max(1) as usize)
            .map(|i| self.uav_altitude(i, tallest))
            .fold(f64::NEG_INFINITY, f64::max);
        let pose = CameraPose {
            position: sets::math::Point3::new(0.0, 0.0, highest),
            yaw: 0.0,
        };
        let sight = Camera::new(self.camera_model(), pose)
            .image_ground_footprint()
            .map_or(f64::INFINITY, |corners| {
                corners.iter().map(|c| c.coords.norm()).fold(0.0, f64::max)
            });
        ((travel + sight) / 10.0).ceil() * 10.0
    }

    /// Whether UAV `uav` asks an external planner for its decisions (`guidance.planner =
    /// "external"`, or `uav` in `guidance.external_uavs`).
    pub fn asks_external(&self, uav: u32) -> bool {
        self.guidance.planner == Planner::External || self.guidance.external_uavs.contains(&uav)
    }

    /// CVS periods per guidance period.
    pub fn steps_per_guidance(&self) -> u64 {
        (self.timing.guidance_period_s / self.timing.cvs_period_s)
            .round()
            .max(1.0) as u64
    }
}

impl Scenario {
    /// Parses and checks a scenario from TOML text; missing keys take the paper's values.
    pub fn from_toml_str(text: &str) -> Result<Scenario, ScenarioError> {
        let table = parse_document(text, "<string>")?;
        resolve(table, &schema()?)
    }

    /// Loads the scenario: the file at `path` (none: the paper's scenario), then each
    /// `KEY=VALUE` override in order, then the key, type and range checks.
    pub fn load(path: Option<&Path>, overrides: &[String]) -> Result<Scenario, ScenarioError> {
        let mut table = match path {
            Some(path) => {
                let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
                    path: path.to_path_buf(),
                    source,
                })?;
                let mut table = parse_document(&text, &path.display().to_string())?;
                anchor_scene(&mut table, path.parent().unwrap_or(Path::new("")));
                table
            }
            None => Table::new(),
        };
        let schema = schema()?;
        for text in overrides {
            Override::parse(text)?.apply(&mut table, &schema)?;
        }
        let mut scenario = resolve(table, &schema)?;
        // An override's relative path is the working directory's; every process of a run
        // gets the same absolute path, wherever it starts.
        for path in [&mut scenario.city.scene, &mut scenario.city.trace] {
            if !path.is_empty()
                && let Ok(absolute) = std::path::absolute(&*path)
            {
                *path = absolute.to_string_lossy().into_owned();
            }
        }
        Ok(scenario)
    }

    /// The scenario as TOML, every key written: what the orchestrator stores next to the
    /// results so a run can be replayed. A valid scenario round-trips exactly through
    /// [`Scenario::from_toml_str`] (floats are written in shortest round-trip form, an infinite
    /// link range as `inf`).
    pub fn to_toml_string(&self) -> String {
        match toml::to_string(self) {
            Ok(text) => text,
            // Only a seed beyond TOML's i64 integers gets here, and `validate` rejects it. A
            // key that does not exist makes loading the text fail loudly instead of silently
            // running the default scenario.
            Err(error) => format!(
                "# This scenario cannot be written as TOML: {error}\nunwritable_scenario = true\n"
            ),
        }
    }

    /// The keys whose values differ from the paper's scenario, as TOML: a short scenario file
    /// that loads back to this scenario (missing keys take the paper's values), and follows
    /// the defaults where it does not set them.
    pub fn to_toml_changes(&self) -> String {
        let (Ok(mine), Ok(paper)) = (Table::try_from(self), Table::try_from(Scenario::default()))
        else {
            return self.to_toml_string();
        };
        let changes = table_changes(mine, &paper);
        toml::to_string(&changes).unwrap_or_else(|_| self.to_toml_string())
    }
}

/// The entries of `mine` that differ from `base`, sub-tables compared key by key.
fn table_changes(mine: Table, base: &Table) -> Table {
    let mut out = Table::new();
    for (key, value) in mine {
        match (value, base.get(&key)) {
            (Value::Table(inner), Some(Value::Table(base_inner))) => {
                let inner = table_changes(inner, base_inner);
                if !inner.is_empty() {
                    out.insert(key, Value::Table(inner));
                }
            }
            (value, Some(b)) if &value == b => {}
            (value, _) => {
                out.insert(key, value);
            }
        }
    }
    out
}

/// The keys of `[city]` that name files.
const CITY_FILES: [&str; 2] = ["scene", "trace"];

/// Takes a relative `city.scene` or `city.trace` of a scenario file from the file's folder
/// `dir`, so that a scenario and its files move together.
fn anchor_scene(table: &mut Table, dir: &Path) {
    let Some(city) = table.get_mut("city").and_then(Value::as_table_mut) else {
        return;
    };
    for key in CITY_FILES {
        if let Some(Value::String(path)) = city.get_mut(key)
            && !path.is_empty()
            && Path::new(path.as_str()).is_relative()
        {
            *path = dir.join(path.as_str()).to_string_lossy().into_owned();
        }
    }
}

/// Parses TOML text into a table, turning syntax errors into line and column.
fn parse_document(text: &str, origin: &str) -> Result<Table, ScenarioError> {
    text.parse::<Table>().map_err(|error| {
        let (line, column) = match error.span() {
            Some(span) => line_and_column(text, span.start),
            None => (1, 1),
        };
        ScenarioError::Syntax {
            origin: origin.to_owned(),
            line,
            column,
            message: error.message().trim().to_owned(),
        }
    })
}

/// 1-based line and character column of byte `offset` in `text`.
fn line_and_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = (0..=offset.min(text.len()))
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0);
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// The default scenario as a TOML table: the schema that user tables are checked against.
///
/// Vectors that are empty by default get one sample element, so that the kind of their
/// elements is known.
fn schema() -> Result<Table, ScenarioError> {
    let mut sample = Scenario::default();
    if sample.uavs.altitudes_m.is_empty() {
        sample.uavs.altitudes_m.push(100.0);
    }
    if sample.guidance.yaw_increments_rad.is_empty() {
        sample.guidance.yaw_increments_rad.push(0.0);
    }
    if sample.guidance.external_uavs.is_empty() {
        sample.guidance.external_uavs.push(0);
    }
    Table::try_from(&sample).map_err(|error| ScenarioError::Schema {
        message: error.to_string(),
    })
}

/// Checks keys and types, deserialises, then checks ranges.
fn resolve(mut table: Table, schema: &Table) -> Result<Scenario, ScenarioError> {
    validate::check_keys_and_types(&mut table, schema)?;
    let scenario: Scenario = Value::Table(table)
        .try_into()
        .map_err(|error: toml::de::Error| ScenarioError::Schema {
            message: error.to_string(),
        })?;
    scenario.validate()?;
    Ok(scenario)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_guidance_reach_is_a_plans_travel_and_the_cameras_farthest_ground() {
        // The top corners of the image from the highest UAV: its forward, sideways and
        // downward components for a camera tilted `t` below the horizon.
        let far_corner = |s: &Scenario| {
            let m = s.camera_model();
            let (side, up) = (
                (m.aperture_rad / 2.0).tan(),
                f64::from(m.rows) / 2.0 / m.focal_px(),
            );
            let t = m.tilt_rad;
            let (forward, down) = (t.cos() + up * t.sin(), t.sin() - up * t.cos());
            let highest = s.uav_altitude(s.uavs.count as usize - 1, s.region.building_height_m[1]);
            highest * forward.hypot(side) / down
        };
        let paper = Scenario::default();
        // 3 periods of 3 s at 10 m/s, and 229.1 m of ground from 110 m up.
        assert!(
            (far_corner(&paper) - 229.08).abs() < 0.01,
            "{}",
            far_corner(&paper)
        );
        assert_eq!(paper.guidance_reach_m(), 320.0);
        let mut fast = paper.clone();
        fast.uavs.speed_mps = 20.0;
        fast.guidance.horizon = 3;
        // 4 periods of 3 s at 20 m/s: 240 + 229.08 m, rounded up.
        assert_eq!(fast.guidance_reach_m(), 470.0);
        let mut low = paper.clone();
        low.uavs.altitudes_m = vec![40.0, 30.0];
        low.uavs.count = 2;
        let expected = 90.0
            + far_corner(&Scenario {
                uavs: UavsConfig {
                    count: 1,
                    altitudes_m: vec![40.0],
                    ..low.uavs.clone()
                },
                ..low.clone()
            });
        assert_eq!(low.guidance_reach_m(), (expected / 10.0).ceil() * 10.0);
    }

    #[test]
    fn line_and_column_count_characters_from_one() {
        let text = "a = 1\nbé = = 2\n";
        let offset = text.find("= 2").unwrap();
        assert_eq!(line_and_column(text, offset), (2, 6));
        assert_eq!(line_and_column(text, 0), (1, 1));
        assert_eq!(line_and_column(text, text.len() + 10), (3, 1));
    }

    #[test]
    fn key_lists_name_their_level() {
        let keys = ["a".to_owned(), "b".to_owned()];
        assert_eq!(list_keys("x", &keys), "the top-level keys are: a, b");
        assert_eq!(list_keys("s.x", &keys), "the keys of [s] are: a, b");
    }

    #[test]
    fn schema_arrays_have_a_sample_element() {
        let schema = schema().unwrap();
        for (section, key) in [("uavs", "altitudes_m"), ("guidance", "yaw_increments_rad")] {
            let array = schema[section][key].as_array().unwrap();
            assert!(
                array.first().is_some_and(Value::is_float),
                "{section}.{key}"
            );
        }
        let uavs = schema["guidance"]["external_uavs"].as_array().unwrap();
        assert!(uavs.first().is_some_and(Value::is_integer));
    }

    /// The `setfleet` keys are written in `[guidance]` itself, between `external_request` and
    /// `hidden_resolution` as before they had a struct of their own: a resolved scenario's
    /// text (which a run cache hashes) does not depend on how the keys are grouped in code.
    #[test]
    fn setfleet_keys_sit_in_guidance_in_their_order() {
        let mut s = Scenario::default();
        s.guidance.setfleet.beam_width = 9;
        s.guidance.setfleet.sweep = SweepPlan::Lanes;
        let text = s.to_toml_string();
        let keys = "external_request = \"turn\"\nlookahead_periods = 6\nbeam_width = 9\n\
                    target_weight = 4.0\ngrowth_horizon_s = 10.0\nspread_m = 60.0\n\
                    sweep = \"lanes\"\ntrack_revisit_s = 0.0\nsecond_viewpoints = false\n\
                    adapt_weights = false\nhidden_resolution = \"estimator\"\n";
        assert!(text.contains(keys), "{text}");
        assert_eq!(
            s.to_toml_changes(),
            "[guidance]\nbeam_width = 9\nsweep = \"lanes\"\n"
        );
        let back = Scenario::from_toml_str("[guidance]\nspread_m = 5\nbeam_width = 3\n").unwrap();
        assert_eq!(back.guidance.setfleet.spread_m, 5.0);
        assert_eq!(back.guidance.setfleet.beam_width, 3);
        assert_eq!(back.guidance.setfleet.lookahead_periods, 6);
    }

    #[test]
    fn external_planner_keys_parse_and_name_their_range() {
        let load = |o: &[&str]| {
            let o: Vec<String> = o.iter().map(|s| (*s).to_owned()).collect();
            Scenario::load(None, &o)
        };
        let s = load(&[
            "guidance.external_uavs=[0,2]",
            "guidance.external_request=\"round_start\"",
            "timing.external_planner_ms=250",
        ])
        .unwrap();
        assert_eq!(s.guidance.external_uavs, [0, 2]);
        assert_eq!(s.guidance.external_request, ExternalRequest::RoundStart);
        assert!(s.asks_external(2) && !s.asks_external(1));
        let all = load(&["guidance.planner=\"external\""]).unwrap();
        assert!((0..all.uavs.count).all(|u| all.asks_external(u)));
        for bad in [
            "guidance.external_uavs=[-1]",
            "guidance.external_uavs=[0.5]",
            "guidance.external_uavs=[9]",
            "guidance.external_request=\"later\"",
        ] {
            let e = load(&[bad]).unwrap_err().to_string();
            let key = bad.split('=').next().unwrap();
            assert!(e.contains(key), "{bad}: {e}");
        }
    }
}
