//! What the observer gathers over a run and hands back when its thread ends
//! ([`ObserverReport`]): the counters, the tracks, the fleet's map, the final sets.
//!
//! Every part of the observer writes into the one report (the loop counts truths and steps,
//! [`reception`](super::reception) counts estimates and merges the map,
//! [`showing`](super::showing) keeps the sinks' files and failures), so the record is
//! defined once and its bookkeeping lives here, beside it, rather than on the loop.

use std::collections::BTreeMap;
use std::time::Duration;

use estimator::fusion::SharedSet;
use estimator::occupancy::OccupancyMap;
use fleet_process::resources::PhaseTimes;
use protocol::frame::CvsFrame;
use protocol::wire::{DropReason, TargetTruth, TruthState, UavCommand};
use sets::grid::GroundGrid;

use super::metrics::FusedSets;
use super::sink;
use super::tally::{AgentTally, Comms, ServiceKind, WindowTally};

/// How the observer's loop ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObserverEnd {
    /// The world announced the end of the run and every truth received was processed.
    EndOfRun,
    /// The orchestrator stopped it.
    Stopped,
}

/// One agent's final knowledge, for the pictures.
#[derive(Clone, Debug)]
pub struct FinalState {
    /// Step.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// The agent whose sets these are (the lowest id measured at that step).
    pub uav: u32,
    /// That agent's fused sets of the step.
    pub sets: FusedSets,
    /// The targets' truth at that step.
    pub targets: Vec<TargetTruth>,
}

/// Everything the observer gathered, returned when its thread ends.
#[derive(Clone, Debug)]
pub struct ObserverReport {
    /// Truth steps processed.
    pub steps: u64,
    /// How it ended.
    pub end: ObserverEnd,
    /// Per agent.
    pub agents: BTreeMap<u32, AgentTally>,
    /// Traffic per service kind.
    pub comms: Comms,
    /// Messages the observer could not use, by reason.
    pub dropped: BTreeMap<String, u64>,
    /// The last measured step's fused sets of one agent.
    pub final_state: Option<FinalState>,
    /// Per agent, its last measured step and its `X̄` after that step's fusion as the
    /// observer rebuilt it: an agent whose run ended there holds the same set.
    pub final_undetected: BTreeMap<u32, (u64, SharedSet)>,
    /// The fleet's map: every map update of every estimate merged.
    pub oem: OccupancyMap,
    /// Each UAV's ground track (x, y) per step.
    pub tracks: Vec<Vec<[f64; 2]>>,
    /// Every UAV's true pose at every step processed (`tracks.csv`).
    pub poses: Vec<crate::results::tracks::UavPose>,
    /// Per UAV, the steps at which the world's geofence overrode its agent's command
    /// ([`protocol::wire::UavTruth::geofence_override`]).
    pub geofence_overrides: Vec<u64>,
    /// Wall time from the first truth to the last step's ack.
    pub stepping: Option<Duration>,
    /// Where the observer thread's time went ([`phase`](super::phase)): thread CPU and wall
    /// time.
    pub phases: PhaseTimes,
    /// The files the sinks made (`run.gif`), to be written into the run's output.
    pub files: Vec<sink::SinkFile>,
    /// Why an essential sink (the recording or the live view) failed, if one did.
    pub sink_failure: Option<String>,
    /// The cars' sets held under windows, and those that meet their holder's window.
    pub windows: WindowTally,
}

impl ObserverReport {
    /// The report of a run of `uavs` UAVs before anything was observed: no steps, a
    /// blank fleet map on `oem_grid`, an empty track per UAV, and
    /// [`ObserverEnd::Stopped`] until the loop sees the end of the run.
    pub(super) fn new(uavs: u32, oem_grid: GroundGrid) -> ObserverReport {
        ObserverReport {
            steps: 0,
            end: ObserverEnd::Stopped,
            agents: BTreeMap::new(),
            comms: Comms::default(),
            dropped: BTreeMap::new(),
            final_state: None,
            final_undetected: BTreeMap::new(),
            oem: OccupancyMap::new(oem_grid),
            tracks: vec![Vec::new(); uavs as usize],
            poses: Vec::new(),
            geofence_overrides: vec![0; uavs as usize],
            stepping: None,
            phases: PhaseTimes::new(),
            files: Vec::new(),
            sink_failure: None,
            windows: WindowTally::default(),
        }
    }

    /// Counts a dropped message as `{what}:{reason}` (e.g. `estimate:other-run`).
    pub(super) fn drop_message(&mut self, what: &str, reason: DropReason) {
        let key = format!("{what}:{}", reason.label());
        *self.dropped.entry(key).or_default() += 1;
    }

    /// Counts an estimate of `uav` dropped, in its agent's tally and by reason.
    pub(super) fn drop_estimate(&mut self, uav: u32, reason: DropReason) {
        self.agents.entry(uav).or_default().estimates_dropped += 1;
        self.drop_message("estimate", reason);
    }

    /// Records the UAVs' tracks and geofence overrides and counts the step's frames and
    /// commands of the `live_agents`.
    pub(super) fn record_fleet(&mut self, truth: &TruthState, live_agents: u32) {
        for u in truth.uavs() {
            if let Some(track) = self.tracks.get_mut(u.id as usize) {
                track.push([u.position[0], u.position[1]]);
            }
            self.poses.push(crate::results::tracks::UavPose {
                step: truth.step,
                time_s: truth.time_s,
                uav: u.id,
                position: u.position,
                yaw: u.yaw,
            });
            if let Some(count) = self.geofence_overrides.get_mut(u.id as usize) {
                *count += u64::from(u.geofence_override());
            }
        }
        self.comms.count(
            ServiceKind::Frames,
            u64::from(live_agents),
            u64::from(live_agents) * std::mem::size_of::<CvsFrame>() as u64,
        );
        self.comms.count(
            ServiceKind::Commands,
            u64::from(live_agents),
            u64::from(live_agents) * std::mem::size_of::<UavCommand>() as u64,
        );
    }
}
