//! How an agent runs ([`AgentConfig`]): the run it joins, its UAV, the scenario, its waits and
//! its checkpoints. The one input of [`super::run`], read by every part of the agent and
//! changed by none.

use std::path::PathBuf;
use std::time::Duration;

use protocol::scenario::Scenario;
use protocol::service::RunId;
use protocol::timeouts::Timeouts;

/// How an agent runs.
#[derive(Clone, Debug)]
pub struct AgentConfig {
    /// The run to join.
    pub run_id: RunId,
    /// This agent's UAV.
    pub uav: u32,
    /// The run's scenario (the same file as the world's).
    pub scenario: Scenario,
    /// The run's waits (peers, token holders, hellos), the same as the world's.
    pub timeouts: Timeouts,
    /// No frame for this long and no live world node: the world is lost.
    pub world_timeout: Duration,
    /// The file this agent checkpoints its state to and resumes from (none: no checkpoints).
    pub checkpoint: Option<PathBuf>,
    /// Checkpoint after the steps that are multiples of this (at least 1; default
    /// [`DEFAULT_CHECKPOINT_EVERY`]).
    pub checkpoint_every: u64,
    /// Fault-injection hook: how long the agent sits on the token before planning, so tests
    /// can kill a holder mid-turn (0 in normal runs; only with the `test-hooks` feature).
    #[cfg(feature = "test-hooks")]
    pub hold_token: Duration,
}

/// Steps between two checkpoints by default: a checkpoint encodes the whole state, whose
/// rasters cover the region, so saving it at every step cost 6 % of a 16-UAV run's CPU on its
/// 1 km region. A restarted agent resumes at most this many steps back, its sets grown by the
/// motion since, and its peers' whole sets bring back what the fleet learned meanwhile.
pub const DEFAULT_CHECKPOINT_EVERY: u64 = 4;

impl AgentConfig {
    /// The default [`Timeouts`] (with the scenario's external planner budget), no checkpoint.
    pub fn new(run_id: RunId, uav: u32, scenario: Scenario) -> Self {
        let timeouts = Timeouts::default().for_scenario(&scenario);
        Self {
            run_id,
            uav,
            scenario,
            timeouts,
            world_timeout: timeouts.world_lost(),
            checkpoint: None,
            checkpoint_every: DEFAULT_CHECKPOINT_EVERY,
            #[cfg(feature = "test-hooks")]
            hold_token: Duration::ZERO,
        }
    }

    /// The checkpoint file of agent `uav` in directory `dir`: `agent-{uav}.ckpt`.
    pub fn checkpoint_in(dir: &std::path::Path, uav: u32) -> PathBuf {
        dir.join(format!("agent-{uav}.ckpt"))
    }
}
