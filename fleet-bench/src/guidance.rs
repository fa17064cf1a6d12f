//! `fleet bench guidance`: the time of one guidance decision on realistic inputs, for both
//! planners: the paper's MPC ([`uav_agent::guidance::paper::plan`], the `paper` variant) and the
//! project's ([`uav_agent::guidance::setfleet::plan`], the `setfleet` variant).
//!
//! Method: the fleet runs in-process ([`fleet`]) so the sets and each UAV's map are a run's.
//! At every guidance step after the warm-up, each UAV's decision is timed as the agent takes it
//! (the same inputs as `uav_agent::agent`: its pose, `X̄` and every `X_j`, the recently hidden
//! ground, the obstacle cells of its map) with 0, 1, 2 and 3 other UAVs' plans in the token
//! (the round's real plans of the other UAVs), `repeats` times each, by each planner on the
//! same inputs. The fleet flies the `paper` variant's scenario; the `setfleet` planner gets the
//! `setfleet` variant's settings (both with the user's `--set` overrides on top). The summary's
//! `decision_ms_median`/`decision_ms_p99` are the paper's MPC, `setfleet_decision_ms_*` the
//! project's, which shares its work with rayon's pool as the agents run it
//! (`setfleet_threads` threads). The fleet then flies again with the setfleet planner on the
//! calling thread only (`setfleet_one_thread_decision_ms_median`), and the bench fails if any
//! decision differs.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use protocol::scenario::Scenario;
use protocol::wire::PlannedView;
use sim::PlanningState;
use uav_agent::guidance::{self, Decision, GuidanceParams};

use super::estimator::{fleet, paper_guidance};
use super::{BenchCase, BenchReport, Metrics, Stats};
use fleet_process::usage::{ScenarioArgs, UsageError};
use protocol::variant::Variant;

/// Most plans of other UAVs put in the token.
const MAX_OTHERS: usize = 3;

/// `fleet bench guidance`.
#[derive(Debug, Args)]
pub struct BenchGuidanceArgs {
    /// The scenario (default: the paper's).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// Steps simulated.
    #[arg(long, default_value_t = 120)]
    pub steps: u64,
    /// Steps simulated before decisions are timed (so the sets and the maps are real).
    #[arg(long, default_value_t = 60)]
    pub warm_up: u64,
    /// Timed decisions per UAV, guidance step and number of plans in the token.
    #[arg(long, default_value_t = 3)]
    pub repeats: u32,
    /// JSON report file.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// A validated `fleet bench guidance`.
#[derive(Debug, Clone)]
pub struct BenchGuidanceConfig {
    /// The scenario the fleet flies (the `paper` variant's).
    pub scenario: Scenario,
    /// The scenario with the `setfleet` variant's settings, for the setfleet planner.
    pub setfleet: Scenario,
    /// Steps simulated.
    pub steps: u64,
    /// Steps before timing.
    pub warm_up: u64,
    /// Repeats per decision.
    pub repeats: u32,
    /// JSON report file.
    pub out: Option<PathBuf>,
}

impl BenchGuidanceArgs {
    /// Checks the counts.
    pub fn validate(&self) -> Result<BenchGuidanceConfig, UsageError> {
        let load = |variant: Variant| {
            ScenarioArgs {
                scenario: self.scenario.scenario.clone(),
                overrides: variant.with_user_overrides(&self.scenario.overrides),
            }
            .load()
        };
        let scenario = load(Variant::Paper)?;
        let setfleet = load(Variant::Setfleet)?;
        if self.warm_up >= self.steps || self.steps > 100_000 {
            return Err(UsageError(format!(
                "--steps {} --warm-up {}: need warm-up < steps <= 100000",
                self.steps, self.warm_up
            )));
        }
        if !(1..=1000).contains(&self.repeats) {
            return Err(UsageError(format!(
                "--repeats {} is out of range; accepted: 1 to 1000",
                self.repeats
            )));
        }
        Ok(BenchGuidanceConfig {
            scenario,
            setfleet,
            steps: self.steps,
            warm_up: self.warm_up,
            repeats: self.repeats,
            out: self.out.clone(),
        })
    }
}

/// The plans of the token for `uav` with `count` of the other UAVs' plans of the round.
fn token_for(uav: usize, round: &[PlannedView], count: usize) -> Vec<PlannedView> {
    round
        .iter()
        .filter(|p| p.uav as usize != uav)
        .take(count)
        .cloned()
        .collect()
}

/// One flight of the fleet with each UAV's decisions timed at every guidance step after the
/// warm-up.
#[derive(Default)]
struct Timings {
    /// The paper's MPC (when timed), by number of plans in the token.
    paper: Vec<Vec<f64>>,
    /// The `setfleet` planner, by number of plans in the token.
    setfleet: Vec<Vec<f64>>,
    /// The `setfleet` planner's decisions, in the order taken.
    decisions: Vec<Decision>,
    obstacle_cells: Vec<f64>,
    sequences: usize,
    setfleet_sequences: usize,
    rounds: u64,
}

/// Flies the fleet and times, for every UAV, number of plans in the token and repeat, the
/// paper's MPC (when `paper`) and then the `setfleet` planner with `setfleet`.
fn time_decisions(
    config: &BenchGuidanceConfig,
    setfleet: &GuidanceParams,
    paper: bool,
) -> anyhow::Result<Timings> {
    let mpc = paper_guidance(&config.scenario);
    let mut sim = fleet(&config.scenario)?;
    let mut t = Timings {
        paper: vec![Vec::new(); MAX_OTHERS + 1],
        setfleet: vec![Vec::new(); MAX_OTHERS + 1],
        ..Timings::default()
    };
    let period = u64::from(mpc.steps_per_period.max(1));
    for _ in 0..config.steps {
        // Time the decisions where the agents take them: after the frame of a guidance step
        // has been folded in and the peers' estimates fused.
        let step = sim.step()?.step;
        if step >= config.warm_up && step.is_multiple_of(period) {
            t.rounds += 1;
            let round: Vec<PlannedView> = sim
                .plan_round(&mpc, &[])?
                .into_iter()
                .map(|d| d.view)
                .collect();
            let fleet: Vec<u32> = (0..sim.uav_count() as u32).collect();
            for (i, estimator) in sim.estimators().iter().enumerate() {
                let state = PlanningState::of(i, estimator)?;
                t.obstacle_cells.push(state.obstacle_count() as f64);
                for count in 0..=MAX_OTHERS {
                    let others = token_for(i, &round, count);
                    let input = state.input(i as u32, &others, &fleet);
                    for _ in 0..config.repeats {
                        if paper {
                            let start = Instant::now();
                            let decision = guidance::paper::plan(&mpc, &input);
                            t.paper[count].push(start.elapsed().as_secs_f64() * 1e3);
                            t.sequences = decision.sequences;
                        }
                        let start = Instant::now();
                        let decision = guidance::setfleet::plan(setfleet, &input);
                        t.setfleet[count].push(start.elapsed().as_secs_f64() * 1e3);
                        t.setfleet_sequences = decision.sequences;
                        t.decisions.push(decision);
                    }
                }
            }
        }
    }
    Ok(t)
}

/// Runs the fleet and times the decisions.
pub fn run(config: &BenchGuidanceConfig) -> anyhow::Result<BenchReport> {
    let load_start = load_average();
    let mut report = BenchReport::new("guidance");
    let (timed, one_thread) = fly_twice(config)?;
    let overall = Stats::from_samples(&all_samples(&timed.paper)).ok_or_else(|| {
        anyhow::anyhow!(
            "no decision was timed: no guidance step in steps {}..{}",
            config.warm_up,
            config.steps
        )
    })?;
    push_decision_cases(&mut report, "", &timed.paper, &overall);
    let setfleet_overall = Stats::from_samples(&all_samples(&timed.setfleet))
        .ok_or_else(|| anyhow::anyhow!("no setfleet decision was timed"))?;
    push_decision_cases(&mut report, "setfleet ", &timed.setfleet, &setfleet_overall);
    summarise(&mut report.summary, &timed, &overall, &setfleet_overall);
    push_one_thread(&mut report, &one_thread);
    insert_load(&mut report.summary, load_start);
    Ok(report)
}

/// Flies the fleet timing both planners, then again with the setfleet planner on the
/// calling thread only; fails if the two flights' setfleet decisions differ.
fn fly_twice(config: &BenchGuidanceConfig) -> anyhow::Result<(Timings, Timings)> {
    let setfleet = GuidanceParams::from_scenario(&config.setfleet);
    let timed = time_decisions(config, &setfleet, true)?;
    // The same flight again with the setfleet planner on the calling thread only (a flight of
    // its own, so that neither run disturbs the other's timing): its time, and the check that
    // sharing the work changes no decision.
    let one_thread = GuidanceParams {
        parallel: false,
        ..setfleet
    };
    let one_thread = time_decisions(config, &one_thread, false)?;
    if let Some(k) = (0..timed.decisions.len().max(one_thread.decisions.len()))
        .find(|&k| timed.decisions.get(k) != one_thread.decisions.get(k))
    {
        anyhow::bail!(
            "the setfleet planner decided differently on one thread (decision {k}), a bug: its \
             decisions must not depend on threads; run `cargo test -p uav-agent \
             the_pool_decides_as_one_thread` and report both: {:?} against {:?}",
            one_thread.decisions.get(k),
            timed.decisions.get(k)
        );
    }
    Ok((timed, one_thread))
}

/// Every timing of `by_others`, whatever the number of plans in the token.
fn all_samples(by_others: &[Vec<f64>]) -> Vec<f64> {
    by_others.iter().flatten().copied().collect()
}

/// Adds a case per number of plans in the token and the case of them all (`overall`), named
/// after `prefix`.
fn push_decision_cases(
    report: &mut BenchReport,
    prefix: &str,
    by_others: &[Vec<f64>],
    overall: &Stats,
) {
    for (count, times) in by_others.iter().enumerate() {
        if let Some(s) = Stats::from_samples(times) {
            report
                .cases
                .push(decision_case(&format!("{prefix}others={count}"), count, &s));
        }
    }
    report
        .cases
        .push(decision_case(&format!("{prefix}all"), MAX_OTHERS, overall));
}

/// The headline figures of the timed flight: both planners' decisions, the rounds, the
/// sequences per decision, the threads, the obstacle cells and the goal.
fn summarise(
    sum: &mut BTreeMap<String, serde_json::Value>,
    timed: &Timings,
    overall: &Stats,
    setfleet_overall: &Stats,
) {
    sum.insert("decision_ms_median".into(), overall.median.into());
    sum.insert("decision_ms_p99".into(), overall.p99.into());
    sum.insert("decisions".into(), overall.n.into());
    sum.insert("rounds".into(), timed.rounds.into());
    sum.insert("sequences_per_decision".into(), timed.sequences.into());
    sum.insert(
        "setfleet_decision_ms_median".into(),
        setfleet_overall.median.into(),
    );
    sum.insert(
        "setfleet_decision_ms_p99".into(),
        setfleet_overall.p99.into(),
    );
    sum.insert(
        "setfleet_sequences_per_decision".into(),
        timed.setfleet_sequences.into(),
    );
    sum.insert(
        "setfleet_threads".into(),
        (rayon::current_num_threads() as u64).into(),
    );
    if let Some(s) = Stats::from_samples(&timed.obstacle_cells) {
        sum.insert("obstacle_cells_median".into(), s.median.into());
    }
    sum.insert("goal_decision_ms_median".into(), 5.0.into());
}

/// The one-thread flight's setfleet decisions: their median and their case.
fn push_one_thread(report: &mut BenchReport, one_thread: &Timings) {
    if let Some(s) = Stats::from_samples(&all_samples(&one_thread.setfleet)) {
        report.summary.insert(
            "setfleet_one_thread_decision_ms_median".into(),
            s.median.into(),
        );
        report
            .cases
            .push(decision_case("setfleet one thread", MAX_OTHERS, &s));
    }
}

/// How busy the machine was at the start (`load_start`) and now: the timings are
/// wall-clock times.
fn insert_load(sum: &mut BTreeMap<String, serde_json::Value>, load_start: Option<f64>) {
    for (key, load) in [
        ("load_average_1m_start", load_start),
        ("load_average_1m_end", load_average()),
    ] {
        if let Some(load) = load {
            sum.insert(key.into(), load.into());
        }
    }
}

/// The 1-minute load average (`/proc/loadavg`; `None` where there is none).
fn load_average() -> Option<f64> {
    std::fs::read_to_string("/proc/loadavg")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn decision_case(name: &str, others: usize, s: &Stats) -> BenchCase {
    let metrics = Metrics::of_stats(s, "_ms");
    let mut params = BTreeMap::new();
    params.insert("others_max".to_owned(), others.into());
    BenchCase {
        name: name.to_owned(),
        params,
        metrics,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::camera::CameraPose;
    use sets::math::Point3;

    fn view(uav: u32) -> PlannedView {
        PlannedView {
            uav,
            poses: vec![CameraPose {
                position: Point3::new(0.0, 0.0, 50.0),
                yaw: 0.0,
            }],
        }
    }

    #[test]
    fn the_token_never_holds_the_planning_uavs_own_plan() {
        let round: Vec<PlannedView> = (0..4).map(view).collect();
        let t = token_for(1, &round, 3);
        assert_eq!(t.iter().map(|p| p.uav).collect::<Vec<_>>(), vec![0, 2, 3]);
        assert_eq!(token_for(0, &round, 1).len(), 1);
        assert!(token_for(2, &round, 0).is_empty());
    }
}
