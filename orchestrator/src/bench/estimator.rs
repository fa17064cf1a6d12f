//! `fleet bench estimator`: one estimator step per UAV per frame of the default scenario, with
//! its phases, the size of the estimate messages and the fusion of a peer's estimate.
//!
//! Method: the world runs in-process ([`FleetSim`]); every step renders each UAV's frame and
//! feeds it to that UAV's [`Estimator`]; only the estimator step is timed (not the rendering).
//! The UAVs fly as they would in a run: every guidance period each plans its yaw with the MPC,
//! in token order, so the views sweep the city and the sets look like a run's. Each step, each
//! UAV's estimate is composed and encoded ([`EstimateOutbox`], [`message::to_bytes`]) and every
//! UAV fuses its peers' estimates ([`PeerEstimate::from_bytes`] + [`Estimator::fuse`]); one
//! fusion is "decode and validate, then fuse" of one peer's message.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Args;
use protocol::flight::UavState;
use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use protocol::wire::PlannedView;
use uav_agent::estimator::message::{self, EstimateOutbox};
use uav_agent::estimator::{Estimator, EstimatorConfig, PeerEstimate, StepTimings};
use uav_agent::guidance::{self, GuidanceParams, ObstacleCell, PlanningInput};
use world_server::World;

use super::{BenchCase, BenchReport, Metrics, Stats};
use crate::usage::{ScenarioArgs, UsageError};

/// Run tag stamped on the frames of the in-process simulation.
const SIM_RUN_TAG: u64 = 1;

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

/// What one simulated step measured, per UAV.
#[derive(Clone, Debug, Default)]
pub struct StepSample {
    /// Step index.
    pub step: u64,
    /// Wall time of each UAV's estimator step.
    pub step_time: Vec<Duration>,
    /// The phases of each UAV's step.
    pub timings: Vec<StepTimings>,
    /// Encoded size of each UAV's estimate, bytes.
    pub message_bytes: Vec<usize>,
    /// Time to compose and encode each UAV's estimate.
    pub encode_time: Vec<Duration>,
    /// Time to decode and validate each peer message fused this step (every receiver, every
    /// sender).
    pub decode_time: Vec<Duration>,
    /// Time to fuse each peer estimate (after decoding).
    pub fuse_time: Vec<Duration>,
}

/// The world and one estimator per UAV, run in-process as a fleet would run them, with the MPC
/// choosing the yaws every guidance period (in token order, each UAV planning around the
/// plans of those before it).
pub struct FleetSim {
    world: World,
    estimators: Vec<Estimator>,
    outboxes: Vec<EstimateOutbox>,
    guidance: GuidanceParams,
    frame: Box<CvsFrame>,
    last_messages: Vec<Vec<u8>>,
}

impl FleetSim {
    /// The world of `scenario` and fresh estimators.
    pub fn new(scenario: &Scenario) -> anyhow::Result<FleetSim> {
        let world = World::new(scenario)?;
        let config = EstimatorConfig::from_scenario(scenario);
        let n = world.uav_count();
        Ok(FleetSim {
            estimators: (0..n).map(|_| Estimator::new(config.clone())).collect(),
            outboxes: (0..n)
                .map(|i| EstimateOutbox::new(i as u32, 1, config.oem_full_every))
                .collect(),
            guidance: GuidanceParams::from_scenario(scenario),
            world,
            frame: CvsFrame::new_boxed(),
            last_messages: vec![Vec::new(); n],
        })
    }

    /// Number of UAVs.
    pub fn uav_count(&self) -> usize {
        self.estimators.len()
    }

    /// The estimators.
    pub fn estimators(&self) -> &[Estimator] {
        &self.estimators
    }

    /// The guidance parameters of the scenario.
    pub fn guidance(&self) -> &GuidanceParams {
        &self.guidance
    }

    /// Each UAV's encoded estimate of the last step.
    pub fn last_messages(&self) -> &[Vec<u8>] {
        &self.last_messages
    }

    /// Whether the current step starts a guidance period.
    pub fn is_guidance_step(&self) -> bool {
        self.world
            .step()
            .is_multiple_of(self.guidance.steps_per_period.max(1) as u64)
    }

    /// One step: every UAV's frame through its estimator (timed), estimates exchanged and
    /// fused, on a guidance step the MPC round, then the world advances.
    pub fn step(&mut self) -> anyhow::Result<StepSample> {
        let n = self.uav_count();
        let mut sample = StepSample {
            step: self.world.step(),
            ..StepSample::default()
        };
        for i in 0..n {
            self.world.render(i, SIM_RUN_TAG, &mut self.frame);
            let start = Instant::now();
            let report = self.estimators[i].step(&self.frame)?;
            sample.step_time.push(start.elapsed());
            sample.timings.push(report.timings);
        }
        for i in 0..n {
            let start = Instant::now();
            let msg = self.outboxes[i].compose(self.estimators[i].state_mut());
            let bytes = message::to_bytes(&msg)?;
            sample.encode_time.push(start.elapsed());
            sample.message_bytes.push(bytes.len());
            self.last_messages[i] = bytes;
        }
        for (i, receiver) in self.estimators.iter_mut().enumerate() {
            for (j, bytes) in self.last_messages.iter().enumerate() {
                if i == j {
                    continue;
                }
                let start = Instant::now();
                let peer = PeerEstimate::from_bytes(bytes, receiver.config())?;
                sample.decode_time.push(start.elapsed());
                let start = Instant::now();
                receiver.fuse(&peer);
                sample.fuse_time.push(start.elapsed());
            }
        }
        if self.is_guidance_step() {
            let plans = self.plan_round(&[])?;
            for (i, (yaw_ref, _)) in plans.into_iter().enumerate() {
                self.world.set_yaw_ref(i, yaw_ref);
            }
        }
        self.world.advance();
        Ok(sample)
    }

    /// One guidance round in token order at the current state: each UAV plans around the plans
    /// of the UAVs before it (and `extra`); returns each UAV's yaw reference and plan.
    pub fn plan_round(&self, extra: &[PlannedView]) -> anyhow::Result<Vec<(f64, PlannedView)>> {
        let mut token: Vec<PlannedView> = extra.to_vec();
        let mut out = Vec::with_capacity(self.uav_count());
        for i in 0..self.uav_count() {
            let input = PlanningState::of(&self.estimators[i])?;
            let decision = guidance::paper::plan(&self.guidance, &input.input(i as u32, &token));
            token.push(decision.view.clone());
            out.push((decision.yaw_ref, decision.view));
        }
        Ok(out)
    }
}

/// What the MPC of one UAV looks at, owned, gathered from its estimator as the agent does it
/// (`uav_agent::agent`, when it takes its turn): its pose, `X̄` and every `X_j`, the ground
/// hidden recently and the obstacle cells of its map.
pub struct PlanningState<'a> {
    state: UavState,
    sets: Vec<&'a protocol::raster::CellSet>,
    hidden: protocol::raster::CellSet,
    obstacles: Vec<ObstacleCell>,
}

impl<'a> PlanningState<'a> {
    /// Gathers the inputs from an estimator that has folded at least one frame.
    pub fn of(estimator: &'a Estimator) -> anyhow::Result<PlanningState<'a>> {
        let st = estimator.state();
        let pose = st
            .pose
            .ok_or_else(|| anyhow::anyhow!("no pose to plan from at step {}", st.step))?;
        Ok(PlanningState {
            state: UavState {
                position: pose.position,
                yaw: pose.yaw,
            },
            sets: st.target_sets().collect(),
            hidden: st.hidden_history.recently_hidden(),
            obstacles: ObstacleCell::known(&st.oem),
        })
    }

    /// The planning input of UAV `uav` with the token's plans `others`.
    pub fn input<'b>(&'b self, uav: u32, others: &'b [PlannedView]) -> PlanningInput<'b> {
        PlanningInput {
            uav,
            state: self.state,
            sets: &self.sets,
            recently_hidden: &self.hidden,
            obstacles: &self.obstacles,
            others,
        }
    }

    /// Obstacle cells known to the map.
    pub fn obstacle_count(&self) -> usize {
        self.obstacles.len()
    }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn stats_of(name: &str, samples: &[f64]) -> anyhow::Result<Stats> {
    Stats::from_samples(samples).ok_or_else(|| anyhow::anyhow!("no sample of {name}"))
}

/// A case of the report from a sample of milliseconds.
fn timing_case(name: &str, unit: &str, s: &Stats) -> BenchCase {
    let mut metrics = Metrics::default();
    metrics.push("median", s.median);
    metrics.push("p10", s.p10);
    metrics.push("p90", s.p90);
    metrics.push("p99", s.p99);
    metrics.push("max", s.max);
    metrics.push("n", s.n as f64);
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
    let mut sim = FleetSim::new(&config.scenario)?;
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
