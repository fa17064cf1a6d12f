//! Why an agent could not start ([`AgentStartError`]) or stopped with an error
//! ([`AgentError`]): the errors every part of the agent returns, kept apart so that the parts
//! and the loop that composes them all read them from one leaf.

use std::time::Duration;

use protocol::codec::EncodeError;
use protocol::ipc::{IpcOpenError, NodeScanError};

use super::links::LinkError;

/// Why an agent could not join its run.
#[derive(Debug, thiserror::Error)]
pub enum AgentStartError {
    /// The UAV index is not in the scenario's fleet.
    #[error("UAV {uav} is outside the fleet: the scenario has {count} UAVs (ids 0..{count})")]
    OutsideFleet {
        /// Requested id.
        uav: u32,
        /// UAVs in the scenario.
        count: u32,
    },
    /// Another live process already is this agent.
    #[error("agent {uav} is already live in run {run}: refusing to start a second one")]
    AlreadyLive {
        /// Requested id.
        uav: u32,
        /// The run.
        run: String,
    },
    /// The run's nodes could not be listed.
    #[error(transparent)]
    Scan(#[from] NodeScanError),
}

/// Why an agent stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum AgentError {
    /// It could not join the run.
    #[error(transparent)]
    Start(#[from] AgentStartError),
    /// Its node, services or ports could not be opened.
    #[error(transparent)]
    Open(#[from] IpcOpenError),
    /// A message could not be sent.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// A message could not be encoded.
    #[error(transparent)]
    Encode(#[from] EncodeError),
    /// No frame came for a long while and the world's node is gone.
    #[error(
        "the world-server of run {run} is gone (no frame for {waited:?} and its node is not alive)"
    )]
    WorldLost {
        /// The run.
        run: String,
        /// How long no frame came.
        waited: Duration,
    },
    /// A guidance step came before any pose.
    #[error("no pose to plan from at step {0}")]
    NoPose(u64),
}

impl AgentError {
    /// Whether the error is the caller's (an argument that cannot work), as opposed to a
    /// failure of the run.
    pub fn is_usage(&self) -> bool {
        matches!(
            self,
            AgentError::Start(AgentStartError::OutsideFleet { .. })
        )
    }
}
