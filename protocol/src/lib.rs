//! # protocol
//!
//! The shared vocabulary of setfleet: everything two processes must agree on. The geometry,
//! the ground grid and the sets are the `sets` crate's.
//!
//! - [`camera`]: the pinhole camera used by both the renderer and the estimator.
//! - [`scenario`]: the TOML scenario with the paper's defaults built in.
//! - [`frame`]: the fixed-size CVS frame rendered in place into shared memory.
//! - [`wire`]: commands, truth, estimates and the guidance token.
//! - [`plan`]: what an agent asks an external planner (Python, say) and the answer it takes.
//! - [`radio`]: the simulated radio links between agents (range, loss, latency), which the
//!   receivers and the observer apply alike.
//! - [`stats`]: order statistics of a sample (benchmarks' timings, message latencies, an
//!   external planner's answer times).
//! - [`service`]: run ids and every iceoryx2 service name.
//! - [`ipc`]: iceoryx2 nodes and services with the fleet's quality of service, wake-up events,
//!   cleanup after dead processes.
//! - [`codec`]: the one place that encodes and decodes variable-size messages.
//! - [`timeouts`]: every bounded wait of a run, derived from one place.
//! - [`resources`]: where a process's time and memory go: CPU clocks, the phase clock, the
//!   kernel's account of a process (CPU time, peak resident memory).
//! - [`process`]: how every setfleet binary starts (logging, arguments, dying with its
//!   parent).
//! - [`usage`]: what every command's arguments share: where the scenario comes from and the
//!   error of bad input.
//! - [`variant`]: the guidance variants, named sets of scenario settings.

pub mod camera;
pub mod codec;
pub mod flight;
pub mod frame;
pub mod ipc;
pub mod plan;
pub mod process;
pub mod radio;
pub mod resources;
pub mod scenario;
pub mod service;
pub mod stats;
pub mod timeouts;
pub mod usage;
pub mod variant;
pub mod wire;
