//! The phases of an agent's time ([`super::AgentReport::phases`]): every part of the agent
//! counts its work and its waits to one of these on the process's clock.

/// Folding a frame into the estimator (predict, correct, the OEM).
pub const ESTIMATE: &str = "estimate";
/// Composing, encoding and sending the agent's estimate.
pub const PUBLISH: &str = "publish";
/// Receiving, decoding and fusing the peers' estimates.
pub const FUSE: &str = "fuse";
/// The planner's decision and passing the token.
pub const PLAN: &str = "plan";
/// Writing the checkpoint.
pub const CHECKPOINT: &str = "checkpoint";
/// Listing the run's nodes (who is alive).
pub const SCAN: &str = "scan";
/// Waiting for the next frame.
pub const WAIT_FRAME: &str = "wait_frame";
/// Waiting for the peers' estimates of the step.
pub const WAIT_PEERS: &str = "wait_peers";
/// Waiting for the token.
pub const WAIT_TOKEN: &str = "wait_token";
/// Waiting for an external planner's answer.
pub const WAIT_PLANNER: &str = "wait_planner";
/// Everything else (commands, tokens read, start-up after the clock started).
pub const OTHER: &str = "other";
