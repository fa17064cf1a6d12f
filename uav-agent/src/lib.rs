//! # uav-agent
//!
//! One UAV of a setfleet run: the process that turns the world's frames into guaranteed sets
//! with the [`estimator`] crate, exchanges them with its peers and steers its camera.
//!
//! - [`agent`]: the process's loop: the iceoryx2 ports, the exchange with the peers, liveness,
//!   checkpoints and the guidance token's turns.
//! - [`guidance`]: the MPC that chooses the next yaw increments (the paper's and `setfleet`'s
//!   objectives, the round-robin token, external planners).
//!
//! ```no_run
//! // An agent of run `demo`, UAV 0, on the default scenario, with the default waits.
//! use std::sync::atomic::AtomicBool;
//! use protocol::scenario::Scenario;
//! use uav_agent::agent::{self, AgentConfig};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let config = AgentConfig::new("demo".parse()?, 0, Scenario::default());
//! let shutdown = AtomicBool::new(false); // set by a signal handler to stop the agent
//! let report = agent::run(config, &shutdown)?;
//! println!("{} frames folded in", report.counters.shared.frames);
//! # Ok(())
//! # }
//! ```

pub mod agent;
pub mod guidance;
