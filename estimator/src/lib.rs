//! # estimator
//!
//! What one UAV knows, and how it evolves: the guaranteed set-membership estimator
//! (docs/design.md §3, "Estimator step") and the occupancy elevation map ([`occupancy`]). The
//! crate knows nothing of processes, radios or guidance: an agent (`uav-agent`), the
//! in-process fleet (`sim`), the observer that decodes estimates (`fleet-observe`) and the
//! benches all drive the same types.
//!
//! ```no_run
//! // One estimator step per frame, then what the peers sent is fused in.
//! use estimator::{Estimator, EstimatorConfig};
//! use protocol::frame::CvsFrame;
//! use protocol::scenario::Scenario;
//!
//! let scenario = Scenario::default();
//! let mut estimator = Estimator::new(EstimatorConfig::from_scenario(&scenario));
//! let frame = CvsFrame::new_boxed(); // in the agent: the sample received from the world
//! match estimator.step(&frame) {
//!     Ok(report) => println!("X̄ covers {:.0} m²", report.undetected_area_m2),
//!     Err(e) => eprintln!("frame refused: {e}"),
//! }
//! ```
//!
//! ## The estimator step
//!
//! An [`Estimator`] pairs an [`EstimatorConfig`] with an explicit [`EstimatorState`]; one call
//! to [`Estimator::step`] folds one CVS frame into the state and returns a [`StepReport`]:
//!
//! 1. predict: `X̄` and every `X_j` grow by `v_max dt`, `dt` the time since the last frame
//!    (skipped frames are covered);
//! 2. correct: `free = P^g ∪ S^o` (this frame's proven-free ground and every obstacle
//!    neighbourhood seen so far); `X̄ <- X̄ \ free`; a target `j` with a box gets
//!    `X_j <- (X_j, or X̄ if new) ∩ X^m_j \ free`; other targets `X_j <- X_j \ free`.
//!
//! Every set that must contain targets is outer and every set removed from them is inner
//! ([`measure`] documents why each frame-derived set is), so no target ever leaves its set.
//!
//! `X̄` and every `X_j` are [`ReachSet`]s: besides their cells they keep, per cell, a lower
//! bound of how far their targets are, so they grow by exactly `v_max dt` per step instead of
//! rounding the growth out to whole cells at every step ([`sets::raster::reach`] argues
//! the guarantee). Removing proven-free ground raises those bounds to the exact gap between
//! each freed cell and the nearest cell that is not free, over the frame's window; a
//! measurement raises them around the measured target ([`TARGET_REACH_MARGIN_M`]).
//! Fusion with peers is in [`fusion`], messages in [`message`], the exchange of measurements
//! in [`exchange`].

pub mod exchange;
pub mod fusion;
mod hidden;
pub mod measure;
pub mod message;
pub mod occupancy;
pub mod predict;
mod snapshot;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use protocol::camera::CameraPose;
use protocol::frame::CvsFrame;
use protocol::scenario::{HiddenWindow, RayAssumption, Scenario, SetGrowth};
use serde::{Deserialize, Serialize};
use sets::grid::GroundGrid;
use sets::math::Real;
use sets::raster::{CellBox, CellSet, ReachSet};

pub use exchange::{ApplyReport, Measurement, Relayed};
pub use fusion::{EstimateSets, FuseReport, PeerEstimate};
pub use hidden::{HiddenHistory, Unseen};
pub use message::{EstimateOutbox, EstimateReadError};

use crate::occupancy::OccupancyMap;
use measure::FrameView;
use snapshot::{cell_set, reach_set, reach_set_map};

/// How far around a measured target, metres, the reach of its set is raised to the exact gap
/// from the measurement: a set left unobserved grows exactly up to this radius, and by the
/// whole-cell dilation beyond it.
pub const TARGET_REACH_MARGIN_M: Real = 40.0;

/// [`TARGET_REACH_MARGIN_M`] in cells of `grid`: also the margin around its box over which a
/// target's set stores its reach ([`ReachSet::with_margin`]).
fn target_reach_margin(grid: &GroundGrid) -> u32 {
    (TARGET_REACH_MARGIN_M / grid.cell_m).ceil() as u32
}

/// Everything the estimator needs from the scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatorConfig {
    /// The bit-raster grid of every set.
    pub grid: GroundGrid,
    /// The occupancy map's grid.
    pub oem_grid: GroundGrid,
    /// `v_max`, m/s.
    pub max_speed_mps: Real,
    /// Target model radius `r_t`, m.
    pub target_radius_m: Real,
    /// Safety distance `r_s` between targets and obstacles, m.
    pub safety_distance_m: Real,
    /// CVS period `T`, s.
    pub period_s: Real,
    /// Depth noise bounds `[w_lo, w_hi]`; each frame's own bounds are added to them.
    pub depth_noise: [Real; 2],
    /// Frames per slot of the hidden-ground history: 1 when the window of eq. (28) counts
    /// frames, the frames of a guidance period when it counts periods
    /// (`guidance.hidden_window`).
    pub hidden_slot_steps: u64,
    /// Slots of hidden ground remembered: the MPC horizon `h`.
    pub hidden_slots: u32,
    /// Obstacle pixels drawn into `S^o` on a lattice of this pitch (plus region borders).
    pub obstacle_pixel_stride: u32,
    /// A message carries the whole OEM every this many messages.
    pub oem_full_every: u64,
    /// How the sets grow between observations (`estimator.sets`).
    pub sets: SetGrowth,
    /// What `S^o` and the map assume of the ray a depth was measured along
    /// (`estimator.depth_ray`).
    pub depth_ray: RayAssumption,
    /// Half-side, metres, of the square around the UAV over which `X̄` keeps its reach
    /// (`estimator.window_m`; infinite: the whole grid). See [`EstimatorConfig::window_of`].
    pub window_m: Real,
}

impl EstimatorConfig {
    /// The configuration of `scenario`.
    pub fn from_scenario(scenario: &Scenario) -> Self {
        Self {
            grid: scenario.grid(),
            oem_grid: scenario.oem_grid(),
            max_speed_mps: scenario.targets.max_speed_mps,
            target_radius_m: scenario.targets.radius_m,
            safety_distance_m: scenario.targets.safety_distance_m,
            period_s: scenario.timing.cvs_period_s,
            depth_noise: scenario.camera.depth_noise,
            hidden_slot_steps: match scenario.guidance.hidden_window {
                HiddenWindow::Frames => 1,
                HiddenWindow::Periods => scenario.steps_per_guidance(),
            },
            hidden_slots: scenario.guidance.horizon.max(1),
            obstacle_pixel_stride: 3,
            oem_full_every: 20,
            sets: scenario.estimator.sets,
            depth_ray: scenario.estimator.depth_ray,
            window_m: scenario.estimator.window_m,
        }
    }

    /// Whether `X̄` keeps its reach over a window around the UAV rather than the whole grid.
    pub fn keeps_window(&self) -> bool {
        self.window_m.is_finite()
    }

    /// The cells of the window around a UAV at `pose` over which `X̄` keeps its reach: the
    /// square of half-side [`EstimatorConfig::window_m`] around the camera's ground point,
    /// clamped to the grid; `None` without a window. (The window is storage: any window
    /// keeps the guarantee, [`sets::raster::reach`] says why.)
    pub fn window_of(&self, pose: &CameraPose) -> Option<CellBox> {
        if !self.keeps_window() {
            return None;
        }
        let (x, y, r) = (pose.position.x, pose.position.y, self.window_m);
        let columns = self.grid.columns_touching(x - r, x + r)?;
        let rows = self.grid.rows_touching(y - r, y + r)?;
        Some(CellBox {
            x0: columns.0,
            y0: rows.0,
            x1: columns.1,
            y1: rows.1,
        })
    }

    /// `X̄` before any frame: the whole grid, kept over a window when one is configured.
    fn undetected_at_start(&self) -> ReachSet {
        if self.keeps_window() {
            ReachSet::full_outside_window(&self.grid)
        } else {
            ReachSet::full(&self.grid)
        }
    }

    /// `set` kept over a window when one is configured ([`ReachSet::keep_window`]).
    fn keep_window(&self, set: ReachSet) -> ReachSet {
        if self.keeps_window() && !set.keeps_window() {
            set.keep_window()
        } else {
            set
        }
    }
}

/// The estimator's whole knowledge, explicit and serialisable (sets as compact encodings).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatorState {
    /// Step of the last frame folded in (0 before any).
    pub step: u64,
    /// Simulated time of that frame, s.
    pub time_s: Real,
    /// Frames folded in so far.
    pub frames: u64,
    /// Camera pose of the last frame.
    pub pose: Option<CameraPose>,
    /// `X̄`, outer: where targets not yet identified can be (it holds every target).
    #[serde(with = "reach_set")]
    pub undetected: ReachSet,
    /// `X_j`, outer, per identified target id.
    #[serde(with = "reach_set_map")]
    pub targets: BTreeMap<u32, ReachSet>,
    /// `S^o`, inner, accumulated: ground within `r_s` of an obstacle, never a target's.
    #[serde(with = "cell_set")]
    pub obstacle_neighbourhood: CellSet,
    /// Union of `P^g` over time: ground proven free at some frame (the explored metric).
    #[serde(with = "cell_set")]
    pub explored: CellSet,
    /// `H^CVS` of the last frame (and of peers' fused since).
    #[serde(with = "cell_set")]
    pub hidden: CellSet,
    /// `P^g` of the last frame (and of peers' fused since): the ground its camera proved free,
    /// which clears the fleet's `H̄` ([`HiddenHistory`]).
    #[serde(with = "cell_set")]
    pub free_ground: CellSet,
    /// Hidden ground of the last guidance periods and hidden ground not seen since.
    pub hidden_history: HiddenHistory,
    /// The occupancy elevation map.
    pub oem: OccupancyMap,
}

impl EstimatorState {
    /// The state before any frame: `X̄` is the whole grid, nothing else is known.
    pub fn new(config: &EstimatorConfig) -> Self {
        let g = &config.grid;
        Self {
            step: 0,
            time_s: 0.0,
            frames: 0,
            pose: None,
            undetected: config.undetected_at_start(),
            targets: BTreeMap::new(),
            obstacle_neighbourhood: CellSet::empty(g),
            explored: CellSet::empty(g),
            hidden: CellSet::empty(g),
            free_ground: CellSet::empty(g),
            hidden_history: HiddenHistory::new(g, config.hidden_slot_steps, config.hidden_slots),
            oem: OccupancyMap::new(config.oem_grid),
        }
    }

    /// Identified target ids.
    pub fn identified(&self) -> impl Iterator<Item = u32> + '_ {
        self.targets.keys().copied()
    }

    /// The sets the guidance shrinks: `X̄`, then every `X_j` by id.
    pub fn target_sets(&self) -> impl Iterator<Item = &CellSet> + '_ {
        std::iter::once(self.undetected.cells()).chain(self.targets.values().map(|s| s.cells()))
    }

    /// Whether every set lives on `config`'s grids (e.g. after deserialising a snapshot).
    pub fn fits(&self, config: &EstimatorConfig) -> bool {
        let probe = CellSet::empty(&config.grid);
        [
            self.undetected.cells(),
            &self.obstacle_neighbourhood,
            &self.explored,
            &self.hidden,
            &self.free_ground,
        ]
        .into_iter()
        .chain(self.targets.values().map(ReachSet::cells))
        .all(|s| s.same_shape(&probe))
            && self.hidden_history.fits(&probe)
            && *self.oem.grid() == config.oem_grid
    }
}

/// Why a frame was refused. The state is untouched when it is.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EstimatorStepError {
    /// The header is inconsistent ([`CvsFrame::is_well_formed`] is false).
    #[error("malformed frame (step {step}): inconsistent header")]
    Malformed {
        /// Step the header claims.
        step: u64,
    },
    /// The frame is not newer than the state: an older frame, or the last one again (a
    /// duplicate is folded in once and counted once).
    #[error("frame of step {frame_step} is not newer than the state's step {state_step}")]
    Stale {
        /// Step of the frame.
        frame_step: u64,
        /// Step of the state.
        state_step: u64,
    },
}

/// Why a state could not be paired with a configuration.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum EstimatorRestoreError {
    /// A set or the map lives on another grid than the configuration's.
    #[error("state does not fit the configured grids")]
    GridMismatch,
}

/// Wall time spent in each phase of a step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StepTimings {
    /// Dilating `X̄` and every `X_j`.
    pub prediction: Duration,
    /// `P^g` and `H^CVS`.
    pub free_ground: Duration,
    /// `X^m_j` of every box.
    pub measurement_sets: Duration,
    /// `S^o` of the frame.
    pub obstacle_sets: Duration,
    /// The occupancy map.
    pub oem: Duration,
    /// Set algebra of the correction and the bookkeeping.
    pub correction: Duration,
    /// The whole step.
    pub total: Duration,
}

/// What one step changed.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StepReport {
    /// Step of the frame.
    pub step: u64,
    /// Frames elapsed since the previous one (more than 1 when frames were skipped).
    pub steps_elapsed: u64,
    /// Area of `X̄` after the step, m².
    pub undetected_area_m2: Real,
    /// Area of each `X_j` after the step, m².
    pub target_areas_m2: BTreeMap<u32, Real>,
    /// Area of this frame's `P^g`, m².
    pub free_ground_area_m2: Real,
    /// Area of the accumulated `S^o`, m².
    pub obstacle_neighbourhood_area_m2: Real,
    /// Area of the explored ground, m².
    pub explored_area_m2: Real,
    /// Area of `H^CVS`, m².
    pub hidden_area_m2: Real,
    /// Targets identified for the first time by this frame.
    pub newly_identified: Vec<u32>,
    /// Targets this frame measured (a usable box).
    pub measured: Vec<u32>,
    /// Targets whose intersection came out empty (a bug signal; the measurement was kept).
    pub empty_intersections: Vec<u32>,
    /// Boxes ignored: outside the image or with an id used twice.
    pub ignored_boxes: u32,
    /// Boxes with no target pixel of usable depth (they tell nothing).
    pub boxes_without_pixels: u32,
    /// Pixels whose depth was not a finite positive number (counted as unknown).
    pub invalid_depth_pixels: u32,
    /// OEM cells changed.
    pub oem_cells_changed: usize,
    /// Time per phase.
    pub timings: StepTimings,
}

/// One UAV's estimator: configuration and state.
#[derive(Clone, Debug)]
pub struct Estimator {
    config: EstimatorConfig,
    state: EstimatorState,
}

impl Estimator {
    /// A fresh estimator (see [`EstimatorState::new`]).
    pub fn new(config: EstimatorConfig) -> Self {
        let state = EstimatorState::new(&config);
        Self { config, state }
    }

    /// Resumes from a saved state, checking that it lives on the configured grids. The reach
    /// of every set is rebuilt from its cells on the configured grid
    /// ([`ReachSet::from_cells_at`]; a snapshot does not store it): the sets then grow from
    /// their cells by the motion since the state's step.
    pub fn with_state(
        config: EstimatorConfig,
        mut state: EstimatorState,
    ) -> Result<Self, EstimatorRestoreError> {
        if !state.fits(&config) {
            return Err(EstimatorRestoreError::GridMismatch);
        }
        let grid = &config.grid;
        let rebuild =
            |set: &ReachSet| ReachSet::from_cells_at(grid, set.cells().clone(), set.clock_m());
        state.undetected = config.keep_window(rebuild(&state.undetected));
        let margin = target_reach_margin(grid);
        for set in state.targets.values_mut() {
            *set = rebuild(set).with_margin(margin);
        }
        Ok(Self { config, state })
    }

    /// The configuration.
    pub fn config(&self) -> &EstimatorConfig {
        &self.config
    }

    /// The state.
    pub fn state(&self) -> &EstimatorState {
        &self.state
    }

    /// The state, mutably (e.g. for the message outbox, which drains the map's changes).
    pub fn state_mut(&mut self) -> &mut EstimatorState {
        &mut self.state
    }

    /// Gives the state back.
    pub fn into_state(self) -> EstimatorState {
        self.state
    }

    /// Folds one frame into the state: predict to the frame's step, measure what the frame
    /// proves, then correct the sets with it. A malformed or stale frame is refused and the
    /// state left as it was.
    pub fn step(&mut self, frame: &CvsFrame) -> Result<StepReport, EstimatorStepError> {
        self.fold(frame, None).map(|(report, _)| report)
    }

    /// [`Estimator::step`], also returning what the frame proved as UAV `uav`'s
    /// [`Measurement`], for its peers to apply ([`Estimator::apply`]).
    pub fn step_sharing(
        &mut self,
        frame: &CvsFrame,
        uav: u32,
    ) -> Result<(StepReport, Measurement), EstimatorStepError> {
        self.fold(frame, Some(uav))
            .map(|(report, m)| (report, m.expect("a measurement was asked for")))
    }

    /// The step, with the frame's [`Measurement`] as UAV `share` when asked.
    fn fold(
        &mut self,
        frame: &CvsFrame,
        share: Option<u32>,
    ) -> Result<(StepReport, Option<Measurement>), EstimatorStepError> {
        let started = Instant::now();
        let h = &frame.header;
        if !frame.is_well_formed() {
            return Err(EstimatorStepError::Malformed { step: h.step });
        }
        if self.state.frames > 0 && h.step <= self.state.step {
            return Err(EstimatorStepError::Stale {
                frame_step: h.step,
                state_step: self.state.step,
            });
        }
        let cfg = &self.config;
        let st = &mut self.state;
        let mut report = StepReport {
            step: h.step,
            steps_elapsed: h.step.saturating_sub(st.step),
            ..StepReport::default()
        };
        if let Some(window) = cfg.window_of(&frame.camera().pose) {
            st.undetected.set_window(&window);
        }
        let clock = predict_sets(cfg, st, &mut report);
        let view = FrameView::new(frame, cfg.depth_noise, cfg.depth_ray);
        report.invalid_depth_pixels = view.invalid_depth_pixels();
        let measured = measure_frame(cfg, st, frame, &view, share.is_some(), &mut report);
        let shared = share.map(|uav| Measurement::of_frame(uav, frame, &measured, &cfg.grid));
        correct_sets(cfg, st, frame, measured, clock, &mut report);
        report.timings.total = started.elapsed();
        Ok((report, shared))
    }

    /// Applies a peer's [`Measurement`] to the state (see [`exchange`]).
    pub fn apply(&mut self, measurement: &Measurement) -> ApplyReport {
        exchange::apply(&self.config, &mut self.state, measurement)
    }

    /// Fuses a peer's estimate into the state (see [`fusion`]).
    pub fn fuse(&mut self, peer: &PeerEstimate) -> FuseReport {
        self.state.fuse(peer, &self.config)
    }
}

/// Prediction: `X̄` and every `X_j` grown by the targets' motion over the steps since the
/// state's (`report.steps_elapsed`), their reach clock moved to the frame's step; returns that
/// clock, m.
fn predict_sets(cfg: &EstimatorConfig, st: &mut EstimatorState, report: &mut StepReport) -> f64 {
    let t = Instant::now();
    let grid = &cfg.grid;
    let radius = predict::motion_radius(report.steps_elapsed, cfg.period_s, cfg.max_speed_mps);
    let clock = predict::motion_radius(report.step, cfg.period_s, cfg.max_speed_mps);
    predict::advance(&mut st.undetected, grid, clock, radius);
    for set in st.targets.values_mut() {
        predict::advance(set, grid, clock, radius);
    }
    report.timings.prediction = t.elapsed();
    clock
}

/// What a frame measured, for the correction.
struct Measurements {
    /// `P^g`: ground the frame proves free.
    free_ground: CellSet,
    /// `H^CVS`: ground the frame's view holds but does not show.
    hidden: CellSet,
    /// `X^m_j` of each usable box, by id (none when no pixel of the box measured the ground).
    targets: Vec<(u32, Option<CellSet>)>,
    /// The cells of `S^o` the frame added, when its measurement is shared.
    obstacles_added: Option<CellSet>,
    /// The map cells the frame changed, when its measurement is shared.
    map_cells: Vec<protocol::wire::OemCellUpdate>,
}

/// Measurement: what `frame` proves (`P^g`, `H^CVS`, each usable box's `X^m_j`), and what it
/// adds to the state as it is measured (`S^o`, the map's observations).
fn measure_frame(
    cfg: &EstimatorConfig,
    st: &mut EstimatorState,
    frame: &CvsFrame,
    view: &FrameView<'_>,
    share: bool,
    report: &mut StepReport,
) -> Measurements {
    let grid = &cfg.grid;
    let t = Instant::now();
    let free_ground = measure::free_ground(view, grid);
    let hidden = measure::hidden_ground(view, grid, &free_ground);
    report.timings.free_ground = t.elapsed();

    let t = Instant::now();
    let boxes = usable_boxes(frame, report);
    let targets: Vec<(u32, Option<CellSet>)> = boxes
        .iter()
        .map(|b| {
            let m = measure::target_measurement(view, grid, b, cfg.target_radius_m);
            (b.id, m)
        })
        .collect();
    report.timings.measurement_sets = t.elapsed();

    let t = Instant::now();
    let before = share.then(|| st.obstacle_neighbourhood.clone());
    measure::add_obstacle_neighbourhood(
        view,
        grid,
        cfg.safety_distance_m,
        cfg.obstacle_pixel_stride,
        &mut st.obstacle_neighbourhood,
    );
    let obstacles_added = before.map(|before| {
        let mut added = st.obstacle_neighbourhood.clone();
        added.and_not_assign(&before);
        added
    });
    report.timings.obstacle_sets = t.elapsed();

    let t = Instant::now();
    let mut map_cells = Vec::new();
    report.oem_cells_changed = if share {
        let (changed, cells) = st.oem.tracked(|map| measure::observe_map(view, map));
        map_cells = cells;
        changed
    } else {
        measure::observe_map(view, &mut st.oem)
    };
    report.timings.oem = t.elapsed();
    Measurements {
        free_ground,
        hidden,
        targets,
        obstacles_added,
        map_cells,
    }
}

/// Correction: the frame's free ground (`P^g ∪ S^o`) leaves `X̄`, each measured target's set
/// is restricted to its measurement and the others lose the free ground near them; then the
/// state takes the frame's step, explored and hidden ground and pose, and the report the
/// sets' areas.
fn correct_sets(
    cfg: &EstimatorConfig,
    st: &mut EstimatorState,
    frame: &CvsFrame,
    measured: Measurements,
    clock: f64,
    report: &mut StepReport,
) {
    let t = Instant::now();
    let grid = &cfg.grid;
    let Measurements {
        free_ground,
        hidden,
        targets,
        ..
    } = measured;
    let corrected = correct(cfg, st, &free_ground, targets, None, clock, None);
    report.boxes_without_pixels += corrected.without_pixels;
    report.newly_identified = corrected.newly_identified;
    report.empty_intersections = corrected.empty_intersections;
    report.measured = corrected.measured;
    st.explored.or_assign(&free_ground);
    st.hidden_history.record(report.step, &hidden, &free_ground);
    st.hidden = hidden;
    st.step = report.step;
    let time_s = frame.header.time_s;
    st.time_s = if time_s.is_finite() {
        time_s
    } else {
        report.step as Real * cfg.period_s
    };
    st.frames += 1;
    let cam = frame.camera();
    st.pose = Some(cam.pose);

    report.undetected_area_m2 = st.undetected.area(grid);
    report.target_areas_m2 = st
        .targets
        .iter()
        .map(|(id, s)| (*id, s.area(grid)))
        .collect();
    report.free_ground_area_m2 = free_ground.area(grid);
    st.free_ground = free_ground;
    report.obstacle_neighbourhood_area_m2 = st.obstacle_neighbourhood.area(grid);
    report.explored_area_m2 = st.explored.area(grid);
    report.hidden_area_m2 = st.hidden.area(grid);
    report.timings.correction = t.elapsed();
}

/// What a correction did to the targets' sets.
#[derive(Debug, Default)]
struct Corrected {
    /// Targets measured, in order.
    measured: Vec<u32>,
    /// Targets identified for the first time.
    newly_identified: Vec<u32>,
    /// Targets whose set missed their measurement (a bug signal; the measurement was kept).
    empty_intersections: Vec<u32>,
    /// Measurements without any cell (no pixel of the box measured the ground).
    without_pixels: u32,
}

/// The correction by one frame's facts, the agent's own (`late` `None`: they hold at the
/// state's clock) or a peer's of an earlier clock (`late`: that clock, m): the free ground
/// (`free_ground ∪ S^o`) leaves `X̄`, each measured target's set is restricted to its
/// measurement `X^m_j` less the free ground (a new target's taken from `X̄`), and the other
/// targets' sets lose the free ground near them.
///
/// `S^o` is taken whole for the agent's own frame (`peer_obstacles` `None`). A peer's
/// measurement (`Some`: the cells of `S^o` it added) is applied after the agent's own frame of
/// the same step, with no prediction between, and that frame's correction left no cell of
/// `S^o` in any set; so only the rows of what the measurement brings can hold cells of `S^o`
/// to remove: its free ground and the two rows around it (where the gaps are measured), its
/// cars' measurements, and the cells of `S^o` it added. Taking `S^o` over those rows only
/// removes the same cells, at the cost of the measurement's rows rather than the region's.
/// (Without an own frame in the step, or when a peer's whole sets brought cells of `S^o` in
/// it, fewer cells may leave the sets: never one that holds a target.)
fn correct(
    cfg: &EstimatorConfig,
    st: &mut EstimatorState,
    free_ground: &CellSet,
    targets: Vec<(u32, Option<CellSet>)>,
    late: Option<Real>,
    clock: Real,
    peer_obstacles: Option<&CellSet>,
) -> Corrected {
    let mut free = free_ground.clone();
    match peer_obstacles {
        None => free.or_assign(&st.obstacle_neighbourhood),
        Some(added) => {
            let rows = [free_ground, added]
                .into_iter()
                .chain(targets.iter().filter_map(|(_, xm)| xm.as_ref()))
                .filter_map(CellSet::row_range)
                .map(|(lo, hi)| (lo.saturating_sub(2), hi.saturating_add(3)))
                .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
            if let Some((lo, hi)) = rows {
                free.or_assign_within(&st.obstacle_neighbourhood, lo..hi);
            }
        }
    }
    let window = free_ground.bounding_box();
    let clearing = Clearing {
        grid: &cfg.grid,
        growth: cfg.sets,
        free: &free,
        blocked: &st.obstacle_neighbourhood,
        late: late.map(|then| (then, clock)),
    };
    clearing.clear(&mut st.undetected, window.as_ref());
    let mut corrected = Corrected::default();
    restrict_measured(
        &clearing,
        &mut st.targets,
        &st.undetected,
        targets,
        clock,
        &mut corrected,
    );
    clear_unmeasured(
        &clearing,
        &mut st.targets,
        &corrected.measured,
        free_ground,
        window.as_ref(),
    );
    corrected
}

/// Each measured target's set restricted to its measurement `X^m_j` less the free ground (a
/// newly identified target's taken from `X̄`, `undetected`); a set that misses its
/// measurement is a bug, reported, and replaced by the measurement alone. The ids measured
/// go to `out`, in order.
fn restrict_measured(
    clearing: &Clearing<'_>,
    sets: &mut BTreeMap<u32, ReachSet>,
    undetected: &ReachSet,
    measurements: Vec<(u32, Option<CellSet>)>,
    clock: f64,
    out: &mut Corrected,
) {
    let margin = target_reach_margin(clearing.grid);
    for (id, measurement) in measurements {
        let Some(mut xm) = measurement else {
            out.without_pixels += 1;
            continue;
        };
        xm.and_not_assign(clearing.free);
        // Where the target can be now: the measurement, grown by the motion since when late.
        let now = clearing.grown_to_now(&xm);
        let mut x = match sets.remove(&id) {
            Some(x) => x,
            None => {
                out.newly_identified.push(id);
                clearing.new_target(undetected, &now, margin)
            }
        };
        if x.intersects(&now) {
            clearing.restrict(&mut x, &xm, margin);
        } else {
            tracing::error!(
                target_id = id,
                clock_m = clock,
                "empty target set after correction: keeping the measurement alone"
            );
            out.empty_intersections.push(id);
            x = ReachSet::full(clearing.grid).with_margin(margin);
            x.advance(clock);
            clearing.restrict(&mut x, &xm, margin);
        }
        sets.insert(id, x);
        out.measured.push(id);
    }
}

/// The frame's free ground leaves the target sets it did not measure, each over the part of
/// `window` (the frame's free ground's box) near it.
fn clear_unmeasured(
    clearing: &Clearing<'_>,
    sets: &mut BTreeMap<u32, ReachSet>,
    measured: &[u32],
    free_ground: &CellSet,
    window: Option<&CellBox>,
) {
    let margin = target_reach_margin(clearing.grid);
    for (id, set) in sets.iter_mut() {
        if measured.contains(id) {
            continue;
        }
        // Free ground the set does not touch tells it nothing it needs now.
        let near = set
            .intersects(free_ground)
            .then(|| set.bounding_box())
            .flatten()
            .and_then(|b| intersect_boxes(&grow_box(&b, margin), window?));
        clearing.clear(set, near.as_ref());
    }
}

/// What a frame proves free, and how the sets' reach learns from it ([`SetGrowth`]).
struct Clearing<'a> {
    grid: &'a GroundGrid,
    growth: SetGrowth,
    /// `P^g ∪ S^o`.
    free: &'a CellSet,
    /// `S^o`: ground no target ever enters.
    blocked: &'a CellSet,
    /// For a late frame's facts: the clock they hold at and the sets' clock, m.
    late: Option<(Real, Real)>,
}

impl Clearing<'_> {
    /// Removes the free ground from `set`, raising its reach over `window` (none: the free
    /// cells only leave the set). Late facts raise the reach with their own clock and remove
    /// only the cells that clock still proves empty ([`ReachSet::clear_since`]); whole-cell
    /// sets keep no reach, and learn nothing from them.
    fn clear(&self, set: &mut ReachSet, window: Option<&CellBox>) {
        match (self.growth, window, self.late) {
            (SetGrowth::Cells, _, Some(_)) | (_, None, Some(_)) => {}
            (_, Some(w), Some((then, _))) => set.clear_since(self.grid, self.free, w, then),
            (SetGrowth::Cells, _, None) | (_, None, None) => set.remove(self.free),
            (SetGrowth::Reach, Some(w), None) => set.clear(self.grid, self.free, w),
            (SetGrowth::Geodesic, Some(w), None) => {
                set.clear_around(self.grid, self.free, self.blocked, w)
            }
        }
    }

    /// Where a target measured in `xm` can be at the sets' clock: `xm` itself, or for late
    /// facts `xm` grown by the motion since.
    fn grown_to_now<'x>(&self, xm: &'x CellSet) -> std::borrow::Cow<'x, CellSet> {
        match self.late {
            Some((then, now)) => predict::grow(xm, self.grid, now - then),
            None => std::borrow::Cow::Borrowed(xm),
        }
    }

    /// The set of a target first measured where `now` says it can be now, from `X̄`
    /// (`undetected`), before it is restricted to its measurement: with reach, a copy of
    /// `X̄ ∩ now` stored over the rows within `margin` of it ([`ReachSet::restricted_copy`]);
    /// whole-cell sets keep no reach, and take `X̄` whole.
    fn new_target(&self, undetected: &ReachSet, now: &CellSet, margin: u32) -> ReachSet {
        match self.growth {
            SetGrowth::Cells => undetected.clone(),
            SetGrowth::Reach | SetGrowth::Geodesic => {
                undetected.restricted_copy(self.grid, now, margin)
            }
        }
    }

    /// Restricts `set` to the measurement `xm`, raising its reach within `margin` cells (late:
    /// [`ReachSet::restrict_since`]).
    fn restrict(&self, set: &mut ReachSet, xm: &CellSet, margin: u32) {
        match (self.growth, self.late) {
            (SetGrowth::Cells, None) => set.intersect(xm),
            (SetGrowth::Cells, Some(_)) => set.intersect(&self.grown_to_now(xm)),
            (_, None) => set.restrict(self.grid, xm, margin),
            (_, Some((then, _))) => set.restrict_since(self.grid, xm, margin, then),
        }
    }
}

/// `b` grown by `margin` cells on every side (not clamped: [`ReachSet::clear`] clamps).
fn grow_box(b: &CellBox, margin: u32) -> CellBox {
    CellBox {
        x0: b.x0.saturating_sub(margin),
        y0: b.y0.saturating_sub(margin),
        x1: b.x1.saturating_add(margin),
        y1: b.y1.saturating_add(margin),
    }
}

/// The common part of two boxes, `None` when they do not overlap.
fn intersect_boxes(a: &CellBox, b: &CellBox) -> Option<CellBox> {
    let c = CellBox {
        x0: a.x0.max(b.x0),
        y0: a.y0.max(b.y0),
        x1: a.x1.min(b.x1),
        y1: a.y1.min(b.y1),
    };
    (c.x0 <= c.x1 && c.y0 <= c.y1).then_some(c)
}

/// The boxes a frame's measurements may use: inside the image and with an id no other box
/// uses (a duplicated id makes every box of that id unusable, the only reading that cannot be
/// wrong). The others are counted in the report.
fn usable_boxes(frame: &CvsFrame, report: &mut StepReport) -> Vec<protocol::frame::TargetBox> {
    let (rows, cols) = (frame.header.rows, frame.header.cols);
    let boxes = frame.boxes();
    let mut uses: BTreeMap<u32, u32> = BTreeMap::new();
    for b in boxes {
        *uses.entry(b.id).or_default() += 1;
    }
    let mut out = Vec::with_capacity(boxes.len());
    for b in boxes {
        if b.is_valid(rows, cols) && uses.get(&b.id) == Some(&1) {
            out.push(*b);
        } else {
            report.ignored_boxes += 1;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use protocol::frame::{Label, TargetBox};

    use super::*;

    fn config() -> EstimatorConfig {
        let mut s = Scenario::default();
        s.region.half_extent_m = 60.0;
        EstimatorConfig::from_scenario(&s)
    }

    /// A small frame looking at flat ground: every pixel ground at its true range.
    fn ground_frame(step: u64) -> Box<CvsFrame> {
        let mut f = CvsFrame::new_boxed();
        let h = &mut f.header;
        h.step = step;
        h.time_s = step as f64 * 0.5;
        h.rows = 24;
        h.cols = 32;
        h.camera_aperture = std::f64::consts::FRAC_PI_4;
        h.camera_tilt = 1.0;
        h.camera_position = [0.0, -30.0, 40.0];
        h.camera_yaw = std::f64::consts::FRAC_PI_2;
        h.depth_noise = [-0.01, 0.01];
        let cam = f.camera();
        for r in 0..24 {
            for c in 0..32 {
                let i = (r * 32 + c) as usize;
                f.labels[i] = Label::Ground as u8;
                f.depth[i] = (40.0 / -cam.centre_ray(r, c).z) as f32;
            }
        }
        f
    }

    #[test]
    fn ground_in_view_leaves_the_undetected_set() {
        let mut e = Estimator::new(config());
        let full = e.state().undetected.cells().count();
        let r = e.step(&ground_frame(0)).expect("step");
        assert!(r.free_ground_area_m2 > 0.0);
        assert!(e.state().undetected.cells().count() < full);
        assert_eq!(
            e.state().explored.count() as f64 * 0.25,
            r.free_ground_area_m2
        );
        // Ten frames later with nothing seen, X̄ grew back by the motion of 10 steps.
        let mut blind = ground_frame(10);
        blind.labels[..24 * 32].fill(Label::Unknown as u8);
        let before = e.state().undetected.cells().count();
        let r = e.step(&blind).expect("step");
        assert_eq!(r.steps_elapsed, 10);
        assert!(e.state().undetected.cells().count() > before);
    }

    #[test]
    fn unobserved_ground_regrows_by_the_motion_not_by_whole_cells() {
        let cfg = config();
        let grid = cfg.grid;
        let mut e = Estimator::new(cfg.clone());
        e.step(&ground_frame(0)).expect("step");
        let after_view = e.state().undetected.cells().clone();
        // Ten blind steps of 1 m each: X̄ may have grown back 10 m into the freed ground
        // (plus one reach unit of rounding), no more; 10 whole-cell dilations reach 15 m.
        let mut blind = ground_frame(10);
        blind.labels[..24 * 32].fill(Label::Unknown as u8);
        e.step(&blind).expect("step");
        let grown = e.state().undetected.cells();
        let reach = 10.0 * cfg.period_s * cfg.max_speed_mps;
        let kept: Vec<(u32, u32)> = after_view.iter().collect();
        let gap_to_kept = |(x, y): (u32, u32)| {
            kept.iter()
                .map(|&(kx, ky)| {
                    let gx = f64::from(x.abs_diff(kx).saturating_sub(1));
                    let gy = f64::from(y.abs_diff(ky).saturating_sub(1));
                    grid.cell_m * gx.hypot(gy)
                })
                .fold(f64::INFINITY, f64::min)
        };
        let freed: Vec<(u32, u32)> = CellSet::full(&grid)
            .iter()
            .filter(|&c| !after_view.contains(c))
            .collect();
        assert!(!freed.is_empty());
        let mut regrown = 0;
        for &c in &freed {
            let gap = gap_to_kept(c);
            if grown.contains(c) {
                regrown += 1;
                assert!(gap <= reach + sets::raster::REACH_UNIT_M + 1e-9, "{c:?}");
            } else {
                assert!(gap > reach - 1e-9, "{c:?} should be reachable");
            }
        }
        let mut old = after_view.clone();
        for _ in 0..10 {
            old = old.dilate(&grid, cfg.period_s * cfg.max_speed_mps);
        }
        assert!(regrown > 0 && grown.count() < old.count());
    }

    #[test]
    fn bad_frames_are_refused_and_bad_parts_ignored() {
        let mut e = Estimator::new(config());
        let mut f = ground_frame(5);
        f.header.rows = 0;
        assert_eq!(e.step(&f), Err(EstimatorStepError::Malformed { step: 5 }));
        assert_eq!(e.state().frames, 0);
        e.step(&ground_frame(5)).expect("step");
        let before = e.state().clone();
        assert_eq!(
            e.step(&ground_frame(5)),
            Err(EstimatorStepError::Stale {
                frame_step: 5,
                state_step: 5
            }),
            "a duplicate frame is refused"
        );
        assert_eq!(e.state(), &before, "and leaves the state as it was");
        assert_eq!(
            e.step(&ground_frame(4)),
            Err(EstimatorStepError::Stale {
                frame_step: 4,
                state_step: 5
            })
        );

        // Targets appear in a fresh estimator's first frame (a target where ground was just
        // proven free would be an inconsistent world).
        let mut e = Estimator::new(config());
        let mut f = ground_frame(6);
        f.depth[3] = f32::NAN;
        f.depth[4] = -1.0;
        f.depth[5] = f32::INFINITY;
        for r in 10..14 {
            for c in 10..14 {
                f.labels[r * 32 + c] = Label::Target as u8;
            }
        }
        let good = TargetBox {
            id: 1,
            r0: 10,
            c0: 10,
            r1: 14,
            c1: 14,
        };
        f.boxes[0] = good;
        f.boxes[1] = TargetBox { id: 2, ..good };
        f.boxes[2] = TargetBox { id: 2, ..good };
        f.boxes[3] = TargetBox {
            id: 3,
            r1: 99,
            ..good
        };
        f.header.box_count = 4;
        let r = e.step(&f).expect("step");
        assert_eq!(r.invalid_depth_pixels, 3);
        assert_eq!(r.ignored_boxes, 3);
        assert_eq!(r.newly_identified, vec![1]);
        assert!(r.empty_intersections.is_empty());
        assert_eq!(e.state().identified().collect::<Vec<_>>(), vec![1]);
        let xj = e.state().targets[&1].cells();
        assert!(xj.count() > 0);
        // X_j came out of X̄ and the measurement, so it lies in X̄ (before later dilations).
        assert_eq!(
            xj.intersection_count(e.state().undetected.cells()),
            xj.count()
        );
    }

    #[test]
    fn state_survives_a_snapshot() {
        let cfg = config();
        let mut e = Estimator::new(cfg.clone());
        e.step(&ground_frame(0)).expect("step");
        let bytes = protocol::codec::encode(e.state()).expect("serialise");
        let back: EstimatorState = protocol::codec::decode(&bytes).expect("deserialise");
        let cells = |s: &EstimatorState| (s.undetected.cells().clone(), s.undetected.clock_m());
        assert_eq!(cells(&back), cells(e.state()));
        let restored = Estimator::with_state(cfg.clone(), back.clone()).expect("restore");
        assert_eq!(cells(restored.state()), cells(e.state()));
        assert_eq!(restored.state().explored, e.state().explored);
        assert_eq!(restored.state().free_ground, e.state().free_ground);
        assert_eq!(restored.state().hidden_history, e.state().hidden_history);
        assert_eq!(restored.state().oem, e.state().oem);
        let other = EstimatorConfig {
            grid: GroundGrid::new(10.0, 0.5),
            ..cfg
        };
        assert_eq!(
            Estimator::with_state(other, back).err(),
            Some(EstimatorRestoreError::GridMismatch)
        );
    }
}
