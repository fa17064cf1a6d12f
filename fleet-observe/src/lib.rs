//! # fleet-observe
//!
//! What setfleet measures and shows of a run, apart from running it:
//!
//! - [`observe`]: the observer thread. It reads the truth, every agent's estimates and the
//!   guidance token over iceoryx2, measures each step ([`observe::StepMetrics`]), checks the
//!   guarantee and acknowledges the step to a lockstep world. It shows each step to the run's
//!   [`observe::sink::Sink`]s, which it knows only through that trait.
//! - [`results`]: what a run writes: `summary.json` ([`results::summary::Summary`], built from
//!   [`results::summary::RunFacts`]), `timeseries.csv`, `metrics.png`, `map.png`,
//!   `sets.png` and `run.gif` (a sink).
//! - [`viewer`]: the run in Foxglove, recorded (`--record`) or live (`--live`) (a sink).
//! - [`pictures`]: plotters drawings with the bundled font.
//! - [`faults`]: the faults a run injects, as the command line writes them and as the
//!   summary reports them.
//!
//! The `fleet` command (the `orchestrator` crate) runs the processes and hands this crate
//! what it needs; nothing here spawns a process.
//!
//! ```
//! use fleet_observe::faults::{Fault, FaultKind};
//! let fault: Fault = "kill:1@30".parse().expect("a fault");
//! assert_eq!((fault.kind, fault.uav, fault.at_s), (FaultKind::Kill, 1, 30.0));
//! ```

pub mod faults;
pub mod observe;
pub mod pictures;
pub mod results;
pub mod viewer;
