//! Why an episode cannot start or go on.

/// Why an episode cannot start or go on.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError {
    /// `--variant` names no variant.
    #[error("no variant {0:?} (paper, kappa0, nomap or setfleet)")]
    Variant(String),
    /// The scenario does not load or fails its checks.
    #[error("bad scenario: {0}")]
    Scenario(String),
    /// The fleet cannot be built from the scenario.
    #[error(transparent)]
    Create(#[from] sim::FleetCreateError),
    /// A step of the fleet failed.
    #[error(transparent)]
    Step(#[from] sim::FleetStepError),
    /// An estimate could not be encoded for the observer.
    #[error("UAV {uav}'s sets could not be encoded: {reason}")]
    Encode {
        /// The UAV.
        uav: u32,
        /// Why.
        reason: String,
    },
    /// An answer for a UAV with no request pending.
    #[error("no request of UAV {0} is pending")]
    NotAsked(u32),
    /// [`crate::Episode::run`] while a request is unanswered.
    #[error("UAV {0}'s request is not answered yet")]
    Unanswered(u32),
}
