//! The command line: raw clap arguments, and their validation into configs whose errors name
//! the flag or scenario key and the accepted range.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use protocol::scenario::Scenario;

/// The `fleet` command: runs, renders and benchmarks setfleet.
#[derive(Debug, Parser)]
#[command(name = "fleet", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: FleetCommand,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum FleetCommand {
    /// Run the fleet once: world-server and agents as processes; results into `--out`.
    Run(crate::run::config::RunArgs),
    /// Run every variant on seeds 1..=N and write the paper's Table I layout.
    Sweep(crate::sweep::SweepArgs),
    /// Render one UAV's camera frame at a given time as pictures.
    Render(RenderArgs),
    /// Measure a part of the system and write a JSON report.
    Bench(BenchArgs),
    /// One process of `fleet bench ipc` (started by it).
    #[command(hide = true)]
    BenchChild(crate::bench::ipc::BenchChildArgs),
}

/// Where the scenario comes from: a file and `KEY=VALUE` overrides.
#[derive(Debug, Clone, Default, Args)]
pub struct ScenarioArgs {
    /// Scenario TOML file (default: the paper's scenario).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Overrides a scenario key, e.g. `--set guidance.kappa=0` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

impl ScenarioArgs {
    /// Loads and checks the scenario.
    pub fn load(&self) -> Result<Scenario, UsageError> {
        Scenario::load(self.scenario.as_deref(), &self.overrides)
            .map_err(|e| UsageError(format!("bad scenario: {e}")))
    }
}

/// `fleet render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// The scenario.
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// UAV index.
    #[arg(long)]
    pub uav: u32,
    /// Simulated time of the frame, seconds (rounded down to a CVS step).
    #[arg(long)]
    pub time: f64,
    /// Output directory (created if needed).
    #[arg(long)]
    pub out: PathBuf,
}

/// `fleet bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// What to measure.
    #[command(subcommand)]
    pub kind: BenchKind,
}

/// The benchmarks.
#[derive(Debug, Subcommand)]
pub enum BenchKind {
    /// CVS frame rendering (ray casts), per thread count.
    Render(BenchRenderArgs),
    /// Moving frames, estimates and the token between processes (iceoryx2 vs a Unix socket).
    Ipc(crate::bench::ipc::BenchIpcArgs),
    /// One estimator step per frame, its phases, message sizes and fusion.
    Estimator(crate::bench::estimator::BenchEstimatorArgs),
    /// One MPC guidance decision.
    Guidance(crate::bench::guidance::BenchGuidanceArgs),
}

/// `fleet bench render`.
#[derive(Debug, Args)]
pub struct BenchRenderArgs {
    /// The scenario (default: the paper's city and camera).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Frames measured per thread count, after warm-up.
    #[arg(long, default_value_t = 60)]
    pub frames: u32,
    /// Thread counts to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = vec![1, 2])]
    pub threads: Vec<usize>,
    /// JSON report file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Bad arguments or scenario: `fleet` exits with code 2 and this message.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("{0}")]
pub struct UsageError(pub String);

/// A validated `fleet render`.
#[derive(Debug, Clone)]
pub struct RenderConfig {
    /// The scenario.
    pub scenario: Scenario,
    /// UAV index, inside the fleet.
    pub uav: u32,
    /// CVS step of the frame.
    pub step: u64,
    /// Output directory.
    pub out: PathBuf,
}

impl RenderArgs {
    /// Checks the UAV and the time against the scenario.
    pub fn validate(&self) -> Result<RenderConfig, UsageError> {
        let scenario = self.scenario.load()?;
        validate_render(scenario, self.uav, self.time, self.out.clone())
    }
}

fn validate_render(
    scenario: Scenario,
    uav: u32,
    time: f64,
    out: PathBuf,
) -> Result<RenderConfig, UsageError> {
    let count = scenario.uavs.count;
    if uav >= count {
        return Err(UsageError(format!(
            "--uav {uav} is out of range; the scenario has UAVs 0..={}",
            count.saturating_sub(1)
        )));
    }
    if !(time.is_finite() && (0.0..=scenario.duration_s).contains(&time)) {
        return Err(UsageError(format!(
            "--time {time} is out of range; accepted: 0 to duration_s = {}",
            scenario.duration_s
        )));
    }
    // A tiny slack so that a time written as a multiple of T is not rounded one step down.
    let step = (time / scenario.timing.cvs_period_s + 1e-9).floor() as u64;
    Ok(RenderConfig {
        scenario,
        uav,
        step,
        out,
    })
}

/// A validated `fleet bench render`.
#[derive(Debug, Clone)]
pub struct BenchRenderConfig {
    /// The scenario.
    pub scenario: Scenario,
    /// Frames per thread count.
    pub frames: u32,
    /// Thread counts.
    pub threads: Vec<usize>,
    /// JSON report file.
    pub out: Option<PathBuf>,
}

impl BenchRenderArgs {
    /// Checks the counts.
    pub fn validate(&self) -> Result<BenchRenderConfig, UsageError> {
        let scenario = self.scenario.load()?;
        if self.frames == 0 {
            return Err(UsageError("--frames must be at least 1".into()));
        }
        if self.threads.is_empty() || self.threads.iter().any(|&t| t == 0 || t > 256) {
            return Err(UsageError(format!(
                "--threads {:?}: each thread count must be 1 to 256",
                self.threads
            )));
        }
        Ok(BenchRenderConfig {
            scenario,
            frames: self.frames,
            threads: self.threads.clone(),
            out: self.out.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_time_and_uav_are_checked_against_the_scenario() {
        let s = Scenario::default();
        let ok = validate_render(s.clone(), 3, 2.5, PathBuf::new()).unwrap();
        assert_eq!(ok.step, 5);
        let e = validate_render(s.clone(), 4, 0.0, PathBuf::new()).unwrap_err();
        assert!(e.0.contains("--uav"), "{e}");
        let e = validate_render(s.clone(), 0, 300.5, PathBuf::new()).unwrap_err();
        assert!(e.0.contains("--time"), "{e}");
        assert!(validate_render(s, 0, f64::NAN, PathBuf::new()).is_err());
    }

    #[test]
    fn cli_parses_the_documented_commands() {
        let cli = Cli::try_parse_from([
            "fleet", "render", "--uav", "1", "--time", "3", "--out", "d", "--set", "seed=2",
        ])
        .unwrap();
        assert!(matches!(cli.command, FleetCommand::Render(ref r) if r.uav == 1));
        let cli = Cli::try_parse_from(["fleet", "bench", "render", "--out", "x.json"]).unwrap();
        assert!(matches!(cli.command, FleetCommand::Bench(_)));
        assert!(Cli::try_parse_from(["fleet", "render", "--frobnicate"]).is_err());
    }
}
