//! The exchange of measurements (docs/design.md §3, "Exchange: measurements, with whole sets
//! where needed"; the scenario's `comms.exchange = "measurements"`).
//!
//! A [`Measurement`] is what one UAV's frame of one step proved, and nothing else: its free
//! ground `P^g`, its hidden ground `H^CVS`, the cells of `S^o` it added, and the measurement
//! `X^m_j` of each car it identified. Its size follows one camera window, not the fleet. A
//! receiver applies a peer's measurement the way its own correction applies its frame
//! ([`super::Estimator::apply`]), in a fixed order (its own frame first, then the peers' by
//! UAV index), so runs stay deterministic.
//!
//! # Why the guarantee holds for any subset of measurements, in any order
//! A measurement of step `k` is a fact about the targets at the motion clock `b_k` of that
//! step: no target is in the closed square of a free cell at `b_k`, car `j` lies in `X^m_j`
//! at `b_k`, and no target ever enters `S^o`.
//!
//! - **In its step** (`k` is the receiver's step) a measurement is applied exactly as the
//!   receiver's own frame: the free cells leave the sets, the reach around them is raised to
//!   their exact gap ([`sets::raster::ReachSet::clear`]), and a measured car's set is
//!   restricted to its measurement.
//! - **Late** (`k` before the receiver's step, e.g. under `comms.latency_ms`), the free cells
//!   no longer prove anything now, but (I1) of [`sets::raster::reach`] does: the reach of a
//!   free cell is raised to `⌊(gap + b_k) / unit⌋`, which keeps (I1) at every later clock
//!   since a target closes a distance at most as fast as the clock grows, and a cell leaves a
//!   set only when its raised reach is above the current clock
//!   ([`sets::raster::ReachSet::clear_since`]). A late car measurement restricts the car's
//!   set to the measurement grown by the motion since
//!   ([`sets::raster::ReachSet::restrict_since`]); a car first learned from a late
//!   measurement starts from `X̄` met with that grown measurement.
//! - A measurement of a step the receiver has not reached is not applied
//!   ([`ApplyReport::ahead`]): the caller keeps it until then.
//!
//! Each operation only raises a lower bound of the reach or removes cells that hold no
//! target, so no sequence of them, with any message lost, late or repeated, drops a target
//! (proptested in `uav-agent/tests/exchange_props.rs`).
//!
//! # Why the sets are no looser than intersection fusion's
//! When every measurement arrives in its step, each receiver applies every UAV's frame, so
//! its sets are those of one estimator that saw every frame of the fleet, and they lie inside
//! the intersection of the sets the agents would fuse (the same proptest checks it):
//!
//! - the cells of the sets before the step lie inside every agent's, and their reach is at
//!   least every agent's (the induction's hypothesis), so prediction adds no cell an agent's
//!   own prediction would not add;
//! - each frame's free ground is applied to them with at least the `S^o` the frame's own UAV
//!   holds, so its gaps, and the reach it raises, are at least that UAV's;
//! - a car first measured by a peer starts from a `X̄` that lies inside the peer's.

use std::collections::BTreeMap;
use std::sync::Arc;

use protocol::camera::CameraPose;
use protocol::frame::CvsFrame;
use protocol::radio::Endpoint;
use protocol::wire::OemCellUpdate;
use sets::grid::GroundGrid;
use sets::raster::CellSet;

use super::fusion::SharedSet;
use super::{EstimatorConfig, EstimatorState, Measurements, correct, predict};
use crate::occupancy::OccupancyMap;

/// What one UAV's frame of one step proved.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    /// The UAV whose frame it is.
    pub uav: u32,
    /// The frame's step.
    pub step: u64,
    /// The camera pose of the frame (`None` when a peer sent one that is not finite).
    pub pose: Option<CameraPose>,
    /// `P^g`: ground the frame proved free at its step.
    pub free_ground: SharedSet,
    /// `H^CVS`: ground the frame's view held but did not show.
    pub hidden: SharedSet,
    /// The cells of `S^o` (ground within `r_s` of an obstacle) the frame added.
    pub obstacles: SharedSet,
    /// `X^m_j` of each car the frame measured, by id.
    pub targets: BTreeMap<u32, SharedSet>,
    /// The map cells the sender's frame changed (a received measurement whose message also
    /// carries whole sets has none here: the estimate carries the sender's whole map).
    pub map_cells: Vec<OemCellUpdate>,
}

/// A peer's measurement as an agent forwards it (`comms.relay_hops`): relaying under a limited
/// radio range. The receiver applies it as any measurement of its step, late by a step per
/// hop, so the guarantee argument above holds for it unchanged.
#[derive(Clone, Debug, PartialEq)]
pub struct Relayed {
    /// How many agents forwarded it so far (at least 1).
    pub hops: u32,
    /// The measurement.
    pub measurement: Measurement,
}

/// What applying a measurement did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ApplyReport {
    /// Steps the measurement is older than the state (0: in its step).
    pub step_lag: u64,
    /// Cars this state had not identified.
    pub new_targets: Vec<u32>,
    /// Cars the measurement measured.
    pub measured: Vec<u32>,
    /// Cars whose set missed the measurement (a bug signal; the measurement was kept).
    pub empty_intersections: Vec<u32>,
    /// The measurement lives on other grids: nothing was applied.
    pub grid_mismatch: bool,
    /// The measurement is of a step the state has not reached: nothing was applied.
    pub ahead: bool,
}

impl Measurement {
    /// The measurement of `frame` as UAV `uav` shares it, from what the estimator measured.
    pub(super) fn of_frame(
        uav: u32,
        frame: &CvsFrame,
        measured: &Measurements,
        grid: &GroundGrid,
    ) -> Self {
        let share = |set: &CellSet| Arc::new(set.clone());
        Self {
            uav,
            step: frame.header.step,
            pose: Some(frame.camera().pose),
            free_ground: share(&measured.free_ground),
            hidden: share(&measured.hidden),
            obstacles: measured
                .obstacles_added
                .as_ref()
                .map_or_else(|| Arc::new(CellSet::empty(grid)), share),
            targets: measured
                .targets
                .iter()
                .filter_map(|(id, m)| m.as_ref().map(|m| (*id, share(m))))
                .collect(),
            map_cells: measured.map_cells.clone(),
        }
    }

    /// Its sender, its step and the sender's pose then: the measurement's end of its link,
    /// which the radio judges ([`protocol::radio::Radio::fuses`]).
    pub fn endpoint(&self) -> Endpoint {
        Endpoint {
            uav: self.uav,
            step: self.step,
            pose: self.pose,
        }
    }

    /// Whether every set lives on the grid of `probe`.
    fn fits(&self, probe: &CellSet) -> bool {
        [&self.free_ground, &self.hidden, &self.obstacles]
            .into_iter()
            .chain(self.targets.values())
            .all(|s| s.same_shape(probe))
    }
}

/// Applies a peer's measurement to `st` (the module docs say why this keeps the guarantee).
pub(super) fn apply(
    cfg: &EstimatorConfig,
    st: &mut EstimatorState,
    m: &Measurement,
) -> ApplyReport {
    let mut report = ApplyReport {
        step_lag: st.step.saturating_sub(m.step),
        ..ApplyReport::default()
    };
    if !m.fits(st.undetected.cells()) {
        report.grid_mismatch = true;
        return report;
    }
    if m.step > st.step {
        report.ahead = true;
        return report;
    }
    let clock = predict::motion_radius(st.step, cfg.period_s, cfg.max_speed_mps);
    let then = predict::motion_radius(m.step, cfg.period_s, cfg.max_speed_mps);
    st.obstacle_neighbourhood.or_assign(&m.obstacles);
    for u in &m.map_cells {
        // Validated when the message was read; a bad cell of a hand-made one is ignored.
        if let Ok((index, cell)) = OccupancyMap::cell_of_update(&cfg.oem_grid, u) {
            st.oem.merge_cell(index, cell);
        }
    }
    let targets = m
        .targets
        .iter()
        .map(|(id, xm)| (*id, Some(CellSet::clone(xm))))
        .collect();
    let late = (m.step < st.step).then_some(then);
    let corrected = correct(
        cfg,
        st,
        &m.free_ground,
        targets,
        late,
        clock,
        Some(&m.obstacles),
    );
    report.new_targets = corrected.newly_identified;
    report.measured = corrected.measured;
    report.empty_intersections = corrected.empty_intersections;
    st.explored.or_assign(&m.free_ground);
    st.hidden.or_assign(&m.hidden);
    st.free_ground.or_assign(&m.free_ground);
    st.hidden_history
        .fuse(st.step, m.step, &m.hidden, &m.free_ground);
    report
}
