//! What the observer shows a run to: a [`Sink`] gets every measured step ([`StepView`]) and,
//! if it asks, one UAV's camera frames and the guidance plans. The observer knows sinks only
//! through this trait; the run chooses them ([`SinkMaker`]): the Foxglove viewer
//! (`crate::viewer::Viewer`) and `run.gif` (`crate::results::maps::animation`).
//!
//! Sinks only read what was measured: the run is the same with them or without.

use std::collections::BTreeMap;

use estimator::occupancy::OccupancyMap;
use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use protocol::wire::{PlannedView, TruthState};
use world_server::scene::Building;

use super::StepMetrics;
use super::metrics::FusedSets;

/// One measured step, as the observer hands it over.
pub struct StepView<'a> {
    /// The truth of the step.
    pub truth: &'a TruthState,
    /// The shown agent and its fused sets (`None` when no estimate of the step arrived).
    pub sets: Option<(u32, &'a FusedSets)>,
    /// The fleet's map.
    pub oem: &'a OccupancyMap,
    /// Whether the map changed since the previous step.
    pub oem_changed: bool,
    /// The plans of the newest guidance round, by UAV (empty unless a sink
    /// [shows plans](Sink::shows_plans)).
    pub plans: &'a BTreeMap<u32, PlannedView>,
    /// The step's metrics.
    pub metrics: &'a StepMetrics,
}

/// A file a sink made, written into the run's output directory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SinkFile {
    /// The file's name in the output directory.
    pub name: &'static str,
    /// Its bytes.
    pub bytes: Vec<u8>,
}

/// Why a sink failed; the observer logs it, and fails the run if the sink is
/// [essential](Sink::essential).
pub type SinkError = Box<dyn std::error::Error + Send + Sync>;

/// Something the observer shows the run to, on the observer's thread.
pub trait Sink {
    /// The phase of the observer's time its work counts to (`summary.json` `resources`).
    fn phase(&self) -> &'static str;

    /// Whether its failure fails the run (a recording the user asked for) rather than only
    /// being logged (`run.gif`).
    fn essential(&self) -> bool;

    /// The UAV whose camera frames it wants, if any.
    fn camera(&self) -> Option<u32> {
        None
    }

    /// Whether it shows the guidance plans (the observer decodes the tokens then).
    fn shows_plans(&self) -> bool {
        false
    }

    /// Where a user can watch it live, once it listens.
    fn live_url(&self) -> Option<String> {
        None
    }

    /// A camera frame of the [`camera`](Sink::camera) UAV.
    fn frame(&mut self, _frame: &CvsFrame) {}

    /// Shows a measured step. An error abandons the sink.
    fn step(&mut self, view: &StepView<'_>) -> Result<(), SinkError>;

    /// Ends it at the end of the run; the file it made, if any.
    fn finish(self: Box<Self>) -> Result<Option<SinkFile>, SinkError>;
}

/// Makes a sink on the observer's thread from the run's scenario and its city (the one the
/// world builds); `Ok(None)` when it has nothing to show. An error fails the run.
pub type SinkMaker =
    Box<dyn FnOnce(&Scenario, &[Building]) -> Result<Option<Box<dyn Sink>>, SinkError> + Send>;
