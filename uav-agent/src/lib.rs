//! # uav-agent
//!
//! One UAV of a setfleet run. This library holds the agent's knowledge and how it evolves:
//!
//! - [`estimator`]: the guaranteed set-membership estimator. An [`estimator::Estimator`] owns an
//!   explicit, serialisable [`estimator::EstimatorState`] (the undetected set `X̄`, one outer set
//!   `X_j` per identified target, the proven-free ground near obstacles `S^o`, the explored
//!   ground, the hidden ground and the map) and advances it one CVS frame at a time with
//!   [`estimator::Estimator::step`], which returns a [`estimator::StepReport`] of what changed.
//!   Peers' estimates are fused with [`estimator::Estimator::fuse`] and exchanged as
//!   [`protocol::wire::EstimateMsg`] through [`estimator::message`].
//! - [`occupancy`]: the occupancy elevation map (OEM), the coarse map of buildings and open
//!   ground the guidance uses to predict occlusions.
//!
//! ```no_run
//! // Agent process: one estimator step per frame, then fuse what the peers sent.
//! use protocol::frame::CvsFrame;
//! use protocol::scenario::Scenario;
//! use uav_agent::estimator::{Estimator, EstimatorConfig};
//!
//! let scenario = Scenario::default();
//! let mut estimator = Estimator::new(EstimatorConfig::from_scenario(&scenario));
//! let frame = CvsFrame::new_boxed(); // in the agent: the sample received from the world
//! match estimator.step(&frame) {
//!     Ok(report) => println!("X̄ covers {:.0} m²", report.undetected_area_m2),
//!     Err(e) => eprintln!("frame refused: {e}"),
//! }
//! ```

pub mod agent;
pub mod estimator;
pub mod guidance;
pub mod occupancy;
