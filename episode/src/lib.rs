//! # episode
//!
//! One run of the fleet in one process, as the Python environments' in-process backend
//! (`SearchEnv(backend="sim")`, docs/python.md) steps it: the world, every UAV's estimator and
//! the estimates' exchange of [`sim::Fleet`], the guidance rounds in token order, and the
//! UAVs the scenario says ask an external planner (`guidance.external_uavs`) asking the caller
//! instead, with the very request bytes an agent sends (`protocol::plan`), answered with the
//! very answer bytes a planner sends. Every step is measured by the observer's own measurement
//! ([`fleet_observe::observe::Measurer`]), so the run's `timeseries.csv` is the one `fleet run`
//! writes for the same scenario, seed and answers: the process backend stays the reference,
//! this one is the same run without processes.
//!
//! - [`EpisodeSpec`]: what `fleet run` is told: the scenario file, the variant, the
//!   overrides, the seed, the duration, the fleet's size, the learning UAVs and when they are
//!   asked; [`EpisodeSpec::scenario`] resolves it as `fleet run` does.
//! - [`Episode`]: the run. [`Episode::run`] steps until a learning UAV asks (its
//!   [`Episode::pending`] requests) or the run ends; [`Episode::answer`] answers a request.
//!   An answer that does not decode is refused as an agent refuses it: that UAV's own planner
//!   decides ([`EpisodeCounts::malformed`]).
//! - [`Episodes`]: several episodes stepped at once over threads, each with its own seed.
//!
//! ```no_run
//! use episode::{Episode, EpisodeSpec};
//! use protocol::plan::{Answer, Steer};
//!
//! let spec = EpisodeSpec {
//!     seed: 7,
//!     learners: vec![0],
//!     duration_s: Some(30.0),
//!     ..EpisodeSpec::default()
//! };
//! let mut episode = Episode::new(&spec)?;
//! while episode.run()? {
//!     for request in episode.pending().to_vec() {
//!         // Keep the heading: the yaw increment 0.
//!         let answer = Answer { steer: Steer::Increments(vec![0.0]), poses: Vec::new(), planner_ns: 0 };
//!         episode.answer(request.uav, &answer.encode(request.step, request.uav))?;
//!     }
//! }
//! println!("{}", episode.timeseries_csv());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod error;
mod run;
mod spec;
mod vector;

pub use error::EpisodeError;
pub use run::{Episode, EpisodeCounts, PendingRequest};
pub use spec::EpisodeSpec;
pub use vector::Episodes;
