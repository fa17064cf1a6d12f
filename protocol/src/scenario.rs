//! The scenario: one TOML file, every key with the paper's value built in (DESIGN.md §5).
//!
//! An empty file (or none) is the paper's scenario. Unknown keys, wrong types and out-of-range
//! values are errors that name the key and the accepted range ([`ScenarioError`]). Any key can
//! be overridden from the command line as `KEY=VALUE` with a TOML value ([`Scenario::load`]).

use serde::{Deserialize, Serialize};

use crate::camera::CameraModel;
use crate::grid::GroundGrid;

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
    /// Share of the ground under buildings.
    pub building_fraction: f64,
    /// Range of building heights `[lo, hi]`.
    pub building_height_m: [f64; 2],
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
}

/// `[uavs]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UavsConfig {
    /// Number of UAVs.
    pub count: u32,
    /// Constant ground speed, m/s.
    pub speed_mps: f64,
    /// Altitudes; empty for distinct altitudes above every building.
    pub altitudes_m: Vec<f64>,
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
}

/// `[timing]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TimingConfig {
    /// CVS and estimation period `T`, seconds.
    pub cvs_period_s: f64,
    /// Guidance period, seconds (a whole number of CVS periods).
    pub guidance_period_s: f64,
}

/// `[estimator]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorConfig {
    /// Bit-raster cell side, metres.
    pub cell_m: f64,
    /// OEM cell side, metres.
    pub oem_cell_m: f64,
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
}

/// `[comms]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommsConfig {
    /// Link range, metres; infinite for perfect links.
    pub range_m: f64,
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            seed: 1,
            duration_s: 300.0,
            region: RegionConfig::default(),
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
        }
    }
}

impl Default for UavsConfig {
    fn default() -> Self {
        Self {
            count: 4,
            speed_mps: 10.0,
            altitudes_m: Vec::new(),
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
        }
    }
}

impl Default for TimingConfig {
    fn default() -> Self {
        Self {
            cvs_period_s: 0.5,
            guidance_period_s: 3.0,
        }
    }
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            cell_m: 0.5,
            oem_cell_m: 5.0,
        }
    }
}

impl Default for GuidanceConfig {
    fn default() -> Self {
        use std::f64::consts::{FRAC_PI_3, FRAC_PI_6};
        Self {
            horizon: 2,
            yaw_increments_rad: vec![-FRAC_PI_3, -FRAC_PI_6, 0.0, FRAC_PI_6, FRAC_PI_3],
            lambda: 1e-5,
            kappa: 1.0,
            use_map: true,
        }
    }
}

impl Default for CommsConfig {
    fn default() -> Self {
        Self {
            range_m: f64::INFINITY,
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

    /// CVS periods per guidance period.
    pub fn steps_per_guidance(&self) -> u64 {
        (self.timing.guidance_period_s / self.timing.cvs_period_s)
            .round()
            .max(1.0) as u64
    }
}
