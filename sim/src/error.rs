//! Why a fleet could not be built or could not step.

use estimator::{EstimateReadError, EstimatorStepError};
use protocol::codec::EncodeError;
use world_server::WorldBuildError;

/// Why [`crate::Fleet::new`] failed.
#[derive(Debug, thiserror::Error)]
pub enum FleetCreateError {
    /// The scenario does not build a world.
    #[error(transparent)]
    World(#[from] WorldBuildError),
}

/// Why a step of the fleet failed (the fleet is then part-way through the step).
#[derive(Debug, thiserror::Error)]
pub enum FleetStepError {
    /// A UAV's estimator refused its frame.
    #[error("UAV {uav}'s estimator refused its frame: {source}")]
    Frame {
        /// The UAV.
        uav: usize,
        /// The estimator's reason.
        source: EstimatorStepError,
    },
    /// A UAV's estimate did not encode.
    #[error("UAV {uav}'s estimate does not encode: {source}")]
    Encode {
        /// The UAV.
        uav: usize,
        /// The encoder's reason.
        source: EncodeError,
    },
    /// A UAV's encoded estimate did not decode, validate or rebuild.
    #[error("UAV {uav}'s estimate does not read back: {source}")]
    Decode {
        /// The sender.
        uav: usize,
        /// The reader's reason.
        source: EstimateReadError,
    },
    /// A UAV had no pose to plan from (its estimator has folded no frame).
    #[error("UAV {uav} has no pose to plan from at step {step}")]
    NoPose {
        /// The UAV.
        uav: usize,
        /// Its estimator's step.
        step: u64,
    },
}
