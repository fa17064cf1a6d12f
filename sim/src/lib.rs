//! # sim
//!
//! The fleet of a run in one process, for tests (`sim/tests/`: the guarantee on every frame,
//! the pinned sets, the occupancy map), benchmarks (`sim/benches/`) and `fleet bench`: the world
//! renders each UAV's frame, each UAV's estimator folds it, every UAV's estimate is encoded as
//! on the wire and decoded and fused by every other, and every guidance period the UAVs decide
//! in token order and fly their decisions. It is the loop the processes of a lockstep run go
//! through, on perfect links and without IPC, written once.
//!
//! - [`Fleet`]: the world and one estimator per UAV. [`Fleet::step`] runs one step; a caller
//!   that looks between the phases runs them itself: [`Fleet::sense`] (frames into the
//!   estimators), [`Fleet::share`] (estimates exchanged and fused), [`Fleet::steer`] (the
//!   guidance round of a guidance step), [`Fleet::advance`] (the world moves on).
//! - [`FleetOptions`]: the run tag, whether the UAVs exchange their estimates, how often an
//!   estimate carries the whole map, and the [`Steering`]: the planners' rounds, or the yaw
//!   references the caller sets ([`Fleet::world_mut`]).
//! - [`StepSample`]: what a step measured, per UAV (the estimator's work timed, never the
//!   rendering), and the round's decisions; [`Sensed`] and [`Fused`]: one UAV's frame folded
//!   and one fusion, shown to the phases' callbacks (a guarantee check looks at every frame,
//!   the truth is the world's, [`Fleet::world`]).
//! - [`PlanningState`]: what one UAV's planner looks at, gathered from its estimator as the
//!   agent gathers it.
//!
//! ```no_run
//! // One process: a small fleet flown by the scenario's planner for 20 steps.
//! use protocol::scenario::Scenario;
//! use sim::{Fleet, FleetOptions, Steering};
//! use uav_agent::guidance::GuidanceParams;
//!
//! let scenario = Scenario::load(None, &["region.half_extent_m=60".to_owned()])?;
//! let options = FleetOptions {
//!     steering: Steering::Guided(Box::new(GuidanceParams::from_scenario(&scenario))),
//!     ..FleetOptions::default()
//! };
//! let mut fleet = Fleet::new(&scenario, options)?;
//! for _ in 0..20 {
//!     let sample = fleet.step()?;
//!     println!("step {}: estimates of {:?} bytes", sample.step, sample.message_bytes);
//! }
//! let identified = fleet.estimators().iter().map(|e| e.state().targets.len()).max();
//! println!("at most {identified:?} targets identified by one UAV");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;
mod fleet;
mod planning;

pub use error::{FleetCreateError, FleetStepError};
pub use fleet::{Fleet, FleetOptions, Fused, Sensed, Steering, StepSample};
pub use planning::PlanningState;
