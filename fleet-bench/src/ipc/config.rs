//! `fleet bench ipc`'s command line and its validation.

use std::path::PathBuf;

use clap::Args;
use protocol::scenario::Scenario;

use fleet_process::usage::{ScenarioArgs, UsageError};

/// Iterations of `--quick`.
const QUICK_ITERATIONS: u64 = 50;
/// Fleet steps simulated to build the estimate message (`--quick`: fewer).
const ESTIMATE_STEPS: u64 = 30;
const QUICK_ESTIMATE_STEPS: u64 = 3;

/// `fleet bench ipc`.
#[derive(Debug, Args)]
pub struct BenchIpcArgs {
    /// The scenario of the estimate message (default: the paper's).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Messages (frames, rounds) per case and phase.
    #[arg(long, default_value_t = 1000)]
    pub iterations: u64,
    /// A short run (50 iterations, a younger estimate message): checks that everything works,
    /// the figures are rough.
    #[arg(long)]
    pub quick: bool,
    /// JSON report file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// A validated `fleet bench ipc`.
#[derive(Debug, Clone)]
pub struct BenchIpcConfig {
    /// The scenario of the estimate message.
    pub scenario: Scenario,
    /// Messages per case and phase.
    pub iterations: u64,
    /// Fleet steps simulated before taking the estimate message.
    pub estimate_steps: u64,
    /// JSON report file.
    pub out: Option<PathBuf>,
}

impl BenchIpcArgs {
    /// Checks the counts.
    pub fn validate(&self) -> Result<BenchIpcConfig, UsageError> {
        let scenario = self.scenario.load()?;
        if !(1..=1_000_000).contains(&self.iterations) {
            return Err(UsageError(format!(
                "--iterations {} is out of range; accepted: 1 to 1000000",
                self.iterations
            )));
        }
        Ok(BenchIpcConfig {
            scenario,
            iterations: if self.quick {
                self.iterations.min(QUICK_ITERATIONS)
            } else {
                self.iterations
            },
            estimate_steps: if self.quick {
                QUICK_ESTIMATE_STEPS
            } else {
                ESTIMATE_STEPS
            },
            out: self.out.clone(),
        })
    }
}
