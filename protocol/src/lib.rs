//! # protocol
//!
//! The shared vocabulary of setfleet: everything two processes must agree on. The geometry,
//! the ground grid and the sets are the `sets` crate's; how a process starts and accounts for
//! itself is `fleet-process`'s. Two models are here because both sides of a link compute
//! them and must get the same numbers: the UAVs' flight (the world flies it, the agents
//! predict with it) and the radio (receivers and the observer apply it alike).
//!
//! - [`camera`]: the pinhole camera used by both the renderer and the estimator.
//! - [`scenario`]: the TOML scenario with the paper's defaults built in.
//! - [`frame`]: the fixed-size CVS frame rendered in place into shared memory.
//! - [`wire`]: commands, truth, estimates and the guidance token.
//! - [`plan`]: what an agent asks an external planner (Python, say) and the answer it takes.
//! - [`flight`]: the UAVs' dynamics (constant speed and altitude, yaw toward a reference),
//!   which the world integrates and the guidance predicts.
//! - [`radio`]: the simulated radio links between agents (range, loss, latency), which the
//!   receivers and the observer apply alike.
//! - [`service`]: run ids and every iceoryx2 service name.
//! - [`ipc`]: iceoryx2 nodes and services with the fleet's quality of service, wake-up events,
//!   cleanup after dead processes.
//! - [`codec`]: the one place that encodes and decodes variable-size messages.
//! - [`timeouts`]: every bounded wait of a run, derived from one place.
//! - [`variant`]: the guidance variants, named sets of scenario settings.

pub mod camera;
pub mod codec;
pub mod flight;
pub mod frame;
pub mod ipc;
pub mod plan;
pub mod radio;
pub mod scenario;
pub mod service;
pub mod timeouts;
pub mod variant;
pub mod wire;
