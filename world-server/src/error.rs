//! Why a world could not be built: the one error of [`World::new`](crate::World::new) and of
//! the generators it calls (city, traffic, fleet) and of the traces it replays.

use protocol::scenario::ScenarioError;

/// Why a world could not be built from a scenario.
#[derive(Debug, thiserror::Error)]
pub enum WorldBuildError {
    /// A value is out of its range ([`protocol::scenario::Scenario::validate`], the loader's
    /// own check, so a scenario built in code is held to the ranges of one read from a file).
    #[error("cannot build the world: {0}")]
    Scenario(#[from] ScenarioError),
    /// The scenario asks for something the generator cannot place (e.g. more cars than the
    /// roads hold with their safety distances).
    #[error("cannot build the world: {0}")]
    Placement(String),
    /// The imported city's scene file cannot be read, or does not fit the scenario.
    #[error("cannot build the world: {0}")]
    Scene(String),
    /// The cars' trace is refused ([`crate::traffic::trace::Trace::check`]).
    #[error("cannot build the world: {0}")]
    Trace(#[from] crate::traffic::trace::TraceError),
    /// SUMO could not drive the cars (missing, failed, or too many cars for the roads).
    #[error("cannot build the world: {0}")]
    Sumo(#[from] crate::traffic::sumo::SumoError),
}
