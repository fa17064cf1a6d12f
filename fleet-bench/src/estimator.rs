//! `fleet bench estimator`: one estimator step per UAV per frame of the default scenario, with
//! its phases, the size of the estimate messages and the fusion of a peer's estimate.
//!
//! Method: the world runs in-process ([`fleet`], a [`sim::Fleet`]); every step renders each
//! UAV's frame and feeds it to that UAV's estimator; only the estimator step is timed (not the
//! rendering). The UAVs fly as they would in a run: every guidance period each plans its yaw
//! with the MPC, in token order, so the views sweep the city and the sets look like a run's. Each step, each
//! UAV's estimate is composed and encoded and every UAV decodes and fuses its peers' estimates
//! ([`sim::Fleet::share`]); one fusion is "decode and validate, then fuse" of one peer's
//! message.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use estimator::StepTimings;
use protocol::scenario::{Planner, Scenario};
use sim::{Fleet, FleetOptions, Steering, StepSample};
use uav_agent::guidance::GuidanceParams;

use super::{BenchCase, BenchReport, Metrics, Stats};
use fleet_process::usage::{ScenarioArgs, UsageError};

/// `fleet bench estimator`.
#[derive(Debug, Args)]
pub struct BenchEstimatorArgs {
    /// The scenario (default: the paper's).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Steps simulated.
    #[arg(long, default_value_t = 120)]
    pub steps: u64,
    /// First steps left out of the statistics (the sets are still the whole region).
    #[arg(long, default_value_t = 10)]
    pub warm_up: u64,
    /// JSON report file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// A validated `fleet bench estimator`.
#[derive(Debug, Clone)]
pub struct BenchEstimatorConfig {
    /// The scenario.
    pub scenario: Scenario,
    /// Steps simulated.
    pub steps: u64,
    /// Steps left out of the statistics.
    pub warm_up: u64,
    /// JSON report file.
    pub out: Option<PathBuf>,
}

impl BenchEstimatorArgs {
    /// Checks the counts.
    pub fn validate(&self) -> Result<BenchEstimatorConfig, UsageError> {
        let scenario = self.scenario.load()?;
        if self.warm_up >= self.steps || self.steps > 100_000 {
            return Err(UsageError(format!(
                "--steps {} --warm-up {}: need warm-up < steps <= 100000",
                self.steps, self.warm_up
            )));
        }
        Ok(BenchEstimatorConfig {
            scenario,
            steps: self.steps,
            warm_up: self.warm_up,
            out: self.out.clone(),
        })
    }
}

/// The MPC `fleet bench` flies the fleet with: the paper's, whatever the scenario's planner,
/// with the scenario's settings.
pub fn paper_guidance(scenario: &Scenario) -> GuidanceParams {
    GuidanceParams {
        planner: Planner::Paper,
        ..GuidanceParams::from_scenario(scenario)
    }
}

/// The world and one estimator per UAV of `scenario`, run in-process as a fleet would run
/// them, with the paper's MPC choosing the yaws every guidance period ([`paper_guidance`], in
/// token order, each UAV planning around the plans of those before it).
pub fn fleet(scenario: &Scenario) -> anyhow::Result<Fleet> {
    let options = FleetOptions {
        steering: Steering::Guided(Box::new(paper_guidance(scenario))),
        ..FleetOptions::default()
    };
    Ok(Fleet::new(scenario, options)?)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn stats_of(name: &str, samples: &[f64]) -> anyhow::Result<Stats> {
    Stats::from_samples(samples).ok_or_else(|| anyhow::anyhow!("no sample of {name}"))
}

/// A case of the report from a sample of milliseconds.
fn timing_case(name: &str, unit: &str, s: &Stats) -> BenchCase {
    let metrics = Metrics::of_stats(s, "");
    let mut params = BTreeMap::new();
    params.insert("unit".to_owned(), unit.into());
    BenchCase {
        name: name.to_owned(),
        params,
        metrics,
    }
}

/// Runs the fleet for `config.steps` steps and reports the estimator's figures.
pub fn run(config: &BenchEstimatorConfig) -> anyhow::Result<BenchReport> {
    let mut report = BenchReport::new("estimator");
    let mut sim = fleet(&config.scenario)?;
    let mut samples = Vec::new();
    for _ in 0..config.steps {
        let s = sim.step()?;
        if s.step >= config.warm_up {
            samples.push(s);
        }
    }
    type Phase = fn(&StepTimings) -> Duration;
    let phases: [(&str, Phase); 6] = [
        ("free_ground", |t| t.free_ground),
        ("measurement_sets", |t| t.measurement_sets),
        ("obstacle_sets", |t| t.obstacle_sets),
        ("oem", |t| t.oem),
        ("prediction", |t| t.prediction),
        ("correction", |t| t.correction),
    ];
    let all =
        |f: &dyn Fn(&StepSample) -> Vec<f64>| -> Vec<f64> { samples.iter().flat_map(f).collect() };
    let step = stats_of(
        "step",
        &all(&|s| s.step_time.iter().map(|d| ms(*d)).collect()),
    )?;
    report.cases.push(timing_case("step", "ms", &step));
    let mut phase_medians = serde_json::Map::new();
    for (name, f) in phases {
        let s = stats_of(
            name,
            &all(&|s| s.timings.iter().map(|t| ms(f(t))).collect()),
        )?;
        phase_medians.insert(format!("{name}_ms_median"), s.median.into());
        report.cases.push(timing_case(name, "ms", &s));
    }
    let encode = stats_of(
        "encode",
        &all(&|s| s.encode_time.iter().map(|d| ms(*d)).collect()),
    )?;
    report.cases.push(timing_case("encode", "ms", &encode));
    let decode = stats_of(
        "decode",
        &all(&|s| s.decode_time.iter().map(|d| ms(*d)).collect()),
    )?;
    report.cases.push(timing_case("decode", "ms", &decode));
    let fuse = stats_of(
        "fuse",
        &all(&|s| s.fuse_time.iter().map(|d| ms(*d)).collect()),
    )?;
    report.cases.push(timing_case("fuse", "ms", &fuse));
    let fusion = stats_of(
        "fusion",
        &all(&|s| {
            s.decode_time
                .iter()
                .zip(&s.fuse_time)
                .map(|(a, b)| ms(*a + *b))
                .collect()
        }),
    )?;
    report.cases.push(timing_case("fusion", "ms", &fusion));
    let bytes = stats_of(
        "message bytes",
        &all(&|s| s.message_bytes.iter().map(|&b| b as f64).collect()),
    )?;
    report.cases.push(timing_case("message", "bytes", &bytes));

    let sum = &mut report.summary;
    sum.insert("step_ms_median".into(), step.median.into());
    sum.insert("step_ms_p99".into(), step.p99.into());
    sum.insert("message_bytes_median".into(), bytes.median.into());
    sum.insert("message_bytes_p99".into(), bytes.p99.into());
    sum.insert("fusion_ms_median".into(), fusion.median.into());
    sum.insert("fusion_ms_p99".into(), fusion.p99.into());
    sum.insert("phases".into(), phase_medians.into());
    sum.insert("uavs".into(), sim.uav_count().into());
    sum.insert("steps".into(), config.steps.into());
    sum.insert("warm_up_steps".into(), config.warm_up.into());
    sum.insert("goal_step_ms_median".into(), 5.0.into());
    sum.insert("goal_message_bytes".into(), (64 * 1024).into());
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warm_up_must_leave_steps_to_measure() {
        let args = BenchEstimatorArgs {
            scenario: ScenarioArgs::default(),
            steps: 10,
            warm_up: 10,
            out: None,
        };
        let e = args.validate().unwrap_err();
        assert!(e.0.contains("--warm-up"), "{e}");
    }
}
