//! # fleet-process
//!
//! What every setfleet process shares apart from what it says on the wire (that is
//! `protocol`'s): how it starts, what its command line shares with the others, and how it
//! accounts for itself.
//!
//! - [`startup`]: how every setfleet binary starts: its log on stderr, its arguments
//!   ([`startup::ChildArgs`] for the three binaries `fleet` starts), and, for a process that
//!   `fleet` or a test started, dying with its parent.
//! - [`usage`]: what every command's arguments share: where the scenario comes from and the
//!   error of bad input (exit code 2).
//! - [`resources`]: where a process's time and memory go: CPU clocks, the phase clock, the
//!   kernel's account of a process (CPU time, peak resident memory).
//! - [`stats`]: order statistics of a sample (benchmarks' timings, message latencies, an
//!   external planner's answer times).
//! - [`clock`]: the UTC wall clock that reports and file names use.
//!
//! ```
//! use fleet_process::stats::Stats;
//! let s = Stats::from_samples(&[3.0, 1.0, 2.0]).expect("a sample");
//! assert_eq!((s.min, s.median, s.max), (1.0, 2.0, 3.0));
//! ```

pub mod clock;
pub mod resources;
pub mod startup;
pub mod stats;
pub mod usage;
