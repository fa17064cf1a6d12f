//! The simulated world: scene, cars and UAVs advanced together, one CVS period at a time.

use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use protocol::wire::TruthState;

/// Why a world could not be built from a scenario.
#[derive(Debug, thiserror::Error)]
pub enum WorldBuildError {
    /// The scenario asks for something the generator cannot place (e.g. more cars than the
    /// roads hold with their safety distances).
    #[error("cannot build the world: {0}")]
    Placement(String),
}

/// The whole simulated world of one run. Deterministic: the same scenario gives the same
/// city, the same trajectories and the same frames, bit for bit.
pub struct World {
    _private: (),
}

impl World {
    /// Builds the city, the cars and the fleet from the scenario's seed.
    pub fn new(scenario: &Scenario) -> Result<World, WorldBuildError> {
        let _ = scenario;
        todo!("world helper")
    }

    /// The scenario the world was built from.
    pub fn scenario(&self) -> &Scenario {
        todo!("world helper")
    }

    /// Steps taken so far (`k`).
    pub fn step(&self) -> u64 {
        todo!("world helper")
    }

    /// Simulated time, seconds (`k * T`).
    pub fn time_s(&self) -> f64 {
        todo!("world helper")
    }

    /// Number of UAVs.
    pub fn uav_count(&self) -> usize {
        todo!("world helper")
    }

    /// Sets the yaw reference of a UAV (ignored for an unknown index or a non-finite value).
    pub fn set_yaw_ref(&mut self, uav: usize, yaw_ref_rad: f64) {
        let _ = (uav, yaw_ref_rad);
        todo!("world helper")
    }

    /// Advances cars and UAVs by one CVS period.
    pub fn advance(&mut self) {
        todo!("world helper")
    }

    /// Renders UAV `uav`'s camera frame at the current step into `frame`, in place (header,
    /// boxes, depth, labels, checksum). `run_tag` goes into the header.
    pub fn render(&self, uav: usize, run_tag: u64, frame: &mut CvsFrame) {
        let _ = (uav, run_tag, frame);
        todo!("world helper")
    }

    /// Writes the ground truth of the current step.
    pub fn truth(&self, run_tag: u64, out: &mut TruthState) {
        let _ = (run_tag, out);
        todo!("world helper")
    }
}
