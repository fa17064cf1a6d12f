//! `summary.json`: the run's final metrics, faults, agents and traffic (docs/design.md §7).
//!
//! The set metrics are the paper's, defined for one UAV on its own fused sets
//! ([`crate::observe::metrics`]). The keys docs/design.md §7 names (`ua_final`, `oa_final`,
//! `explored_final`, `target_set_area_mean`, `loc_error_mean_m`, `identified_final`,
//! `time_all_identified_s`) are the **mean over agents** of each agent's own metric; the same
//! keys suffixed `_worst` are the worst agent's (largest UA, OA, area, error and time, smallest
//! explored and identified), and `agents[i].metrics` holds each agent's own. Fleet-wide values
//! are `violations` (every published estimate checked) and `identified_any_final` /
//! `time_all_identified_any_s` (targets identified by any agent).
//!
//! A `*_final` value is read at the last measured step, over the agents measured then; a
//! `*_mean` value is the mean over the steps where it exists of the per-step mean over agents
//! (or worst agent). `time_all_identified_s` is the mean over the agents measured at the last
//! step of the time each first held every target, `null` if one of them never did.
//!
//! `resources` holds where the run's time and memory went: CPU time, peak resident memory
//! and the phases of every process, and the totals ([`super::resources`]).
//!
//! Two runs of the same scenario and seed in lockstep give byte-identical summaries except
//! for what depends on the wall clock or the machine's load, which lives only under keys
//! named `wall_s`, `real_time_factor`, `timing` and `resources` (at any depth), so a
//! comparison can drop them. Maps are ordered; floats are written as computed.

use std::collections::BTreeMap;
use std::io::Write;

use serde::{Deserialize, Serialize};

use protocol::scenario::Scenario;
use protocol::wire::AgentStats;

use super::resources::Resources;
use crate::faults::{self, FaultRecord};
use crate::observe::metrics::SetMetrics;
use crate::observe::tally::{AgentTally, ServiceKind};
use crate::observe::{ObserverReport, StepMetrics};
use fleet_process::stats::Stats;

/// The summary of a run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Summary {
    /// Scenario seed.
    pub seed: u64,
    /// The guidance variant (`paper`, `kappa0`, `nomap`, `setfleet`).
    pub variant: String,
    /// UAVs in the fleet.
    pub uavs: u32,
    /// Targets in the world.
    pub targets: u32,
    /// `lockstep` or `realtime`.
    pub mode: String,
    /// Scenario duration, seconds.
    pub duration_s: f64,
    /// Simulated time measured, seconds (steps x T).
    pub sim_s: f64,
    /// Wall time of the run, from starting the processes to the end of the world, seconds.
    pub wall_s: f64,
    /// `sim_s / wall_s`.
    pub real_time_factor: f64,
    /// Steps measured.
    pub steps: u64,
    /// Whether the run was interrupted (SIGINT/SIGTERM) or failed before its end.
    pub interrupted: bool,
    /// Truth-outside-set events (must be 0).
    pub violations: u64,
    /// Explored ground at the last measured step, fraction of the region, mean over agents.
    pub explored_final: Option<f64>,
    /// UA (undetected area) at the last measured step, fraction, mean over agents.
    pub ua_final: Option<f64>,
    /// OA (undetected area in occluded ground) at the last measured step, fraction, mean
    /// over agents.
    pub oa_final: Option<f64>,
    /// Mean target-set area over the steps with an identified target, fraction, mean over
    /// agents.
    pub target_set_area_mean: Option<f64>,
    /// Mean localisation error over the steps with an identified target, metres, mean over
    /// agents.
    pub loc_error_mean_m: Option<f64>,
    /// Targets identified at the last measured step, mean over agents.
    pub identified_final: f64,
    /// First time an agent held every target, seconds, mean over agents (`null` if one
    /// never did).
    pub time_all_identified_s: Option<f64>,
    /// First time the mean over agents of UA fell below 25 %, seconds (`null` if it never
    /// did).
    pub time_ua_below_25_s: Option<f64>,
    /// First time the mean over agents of UA fell below 15 %, seconds (`null` if it never
    /// did).
    pub time_ua_below_15_s: Option<f64>,
    /// `explored_final` of the worst agent (least explored).
    pub explored_final_worst: Option<f64>,
    /// `ua_final` of the worst agent.
    pub ua_final_worst: Option<f64>,
    /// `oa_final` of the worst agent.
    pub oa_final_worst: Option<f64>,
    /// Mean over steps of the largest target-set area of an agent.
    pub target_set_area_mean_worst: Option<f64>,
    /// Mean over steps of the largest localisation error of an agent, metres.
    pub loc_error_mean_m_worst: Option<f64>,
    /// `identified_final` of the worst agent.
    pub identified_final_worst: f64,
    /// `time_all_identified_s` of the slowest agent.
    pub time_all_identified_s_worst: Option<f64>,
    /// Targets identified by any agent at the last measured step (fleet-wide).
    pub identified_any_final: u32,
    /// First time every target was identified by some agent, seconds (fleet-wide).
    pub time_all_identified_any_s: Option<f64>,
    /// Faults injected (`--fault`s and the `--chaos` schedule), in the order they applied.
    pub faults: Vec<FaultRecord>,
    /// The `--chaos` seed (`null` without `--chaos`).
    pub chaos_seed: Option<u64>,
    /// Hosts the processes were spread over (`fleet run --hosts`; 1: one host, no bridge).
    pub hosts: u16,
    /// The largest resync of a restarted or resumed agent, steps (`null` when none was
    /// measured; see [`crate::faults`]).
    pub resync_steps_max: Option<u64>,
    /// The mean resync over the restarts and pauses that have one, steps.
    pub resync_steps_mean: Option<f64>,
    /// UAV-steps at which the world's geofence overrode an agent's command, summed over the
    /// UAVs (each agent's count is in `agents`): how often the planner's plans were not the
    /// ones flown near the border (`guidance.border`).
    pub geofence_overrides: u64,
    /// The cars' sets the agents held under windows and those that met their holder's window
    /// (absent without windows smaller than the region).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub windows: Option<WindowsSummary>,
    /// Per agent.
    pub agents: Vec<AgentSummary>,
    /// Traffic per service kind.
    pub comms: BTreeMap<String, CommsSummary>,
    /// What the observer could not use.
    pub observer: ObserverSummary,
    /// CPU time, peak memory and phases per process, and totals.
    pub resources: Resources,
    /// Values that differ between two runs of the same scenario and seed.
    pub timing: RunTiming,
}

/// One agent over the run (summed over its incarnations).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AgentSummary {
    /// UAV index.
    pub uav: u32,
    /// Frames folded into the estimator, as of the agent's last estimate.
    pub steps_processed: u64,
    /// Estimates the agent published.
    pub estimates_sent: u64,
    /// Peer estimates the agent fused, as of its last estimate.
    pub estimates_received: u64,
    /// Estimates the observer decoded.
    pub estimates_observed: u64,
    /// Peer messages the agent dropped.
    pub messages_dropped: u64,
    /// Guidance decisions taken.
    pub decisions: u64,
    /// Decisions taken after waiting out a silent token holder.
    pub token_timeouts: u64,
    /// Peer estimates the simulated radio lost on their way to the agent (`comms.loss`), as
    /// of its last estimate.
    pub estimates_lost: u64,
    /// Tokens the simulated radio lost on their way to the agent.
    pub tokens_lost: u64,
    /// Peer measurements the agent applied from a copy another agent forwarded
    /// (`comms.relay_hops`), as of its last estimate.
    pub relayed_applied: u64,
    /// Peer measurements the agent forwarded, as of its last estimate.
    pub relayed_sent: u64,
    /// Decisions the agent took from an external planner's answer, as of its last estimate
    /// (docs/python.md).
    pub external_decisions: u64,
    /// Decisions its fallback planner took for want of a valid answer in time.
    pub external_fallbacks: u64,
    /// Fingerprint ([`sets::raster::CellSet::digest`]) of the agent's `X̄` after its last
    /// measured step's fusion, as the observer rebuilt it: the agent's own report
    /// (`final_undetected_digest` in its log) holds the same value when the observer
    /// reproduced its fusions exactly and the run ended at that step.
    pub final_undetected_digest: Option<u64>,
    /// That step.
    pub final_measured_step: Option<u64>,
    /// Restarts injected.
    pub restarts: u64,
    /// Steps at which the world's geofence overrode the agent's command (its turn back to
    /// the centre flown instead of the agent's yaw reference).
    pub geofence_overrides: u64,
    /// The set metrics of this agent's own fused sets.
    pub metrics: MetricFinals,
}

impl AgentSummary {
    /// The summary of UAV `uav` as far as the counters its estimates carry go (`counters`,
    /// summed over its incarnations); every other field at its default.
    pub fn of_counters(uav: u32, counters: AgentStats) -> AgentSummary {
        // Every counter by name: one added to the record does not compile until summary.json
        // gives it a key here (its keys and their order are fixed) or leaves it out.
        let AgentStats {
            frames,
            // In the agent's own report only.
            frames_refused: _,
            estimates_received,
            messages_dropped,
            decisions,
            token_timeouts,
            estimates_lost,
            tokens_lost,
            relayed_applied,
            relayed_sent,
            external_decisions,
            external_fallbacks,
        } = counters;
        AgentSummary {
            uav,
            steps_processed: frames,
            estimates_received,
            messages_dropped,
            decisions,
            token_timeouts,
            estimates_lost,
            tokens_lost,
            relayed_applied,
            relayed_sent,
            external_decisions,
            external_fallbacks,
            ..AgentSummary::default()
        }
    }
}

/// The summary values of one series of set metrics: one agent's, or the per-step mean over
/// agents or worst agent (see the module docs). Fractions of the region, seconds, metres.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MetricFinals {
    /// Explored ground at the last step of the series.
    pub explored_final: Option<f64>,
    /// UA at the last step.
    pub ua_final: Option<f64>,
    /// OA at the last step.
    pub oa_final: Option<f64>,
    /// Target-set area, mean over the steps that have one.
    pub target_set_area_mean: Option<f64>,
    /// Localisation error, mean over the steps that have one.
    pub loc_error_mean_m: Option<f64>,
    /// Identified targets at the last step.
    pub identified_final: Option<f64>,
    /// First time `targets` targets were identified.
    pub time_all_identified_s: Option<f64>,
}

impl MetricFinals {
    /// The values of a series of `(time, metrics)` in time order, in a world of `targets`.
    pub fn of<'a>(
        series: impl IntoIterator<Item = (f64, &'a SetMetrics)>,
        targets: u32,
    ) -> MetricFinals {
        let series: Vec<(f64, &SetMetrics)> = series.into_iter().collect();
        let last = series.last().map(|(_, s)| *s);
        let mean_of = |f: fn(&SetMetrics) -> Option<f64>| {
            let v: Vec<f64> = series.iter().filter_map(|(_, s)| f(s)).collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        MetricFinals {
            explored_final: last.map(|s| s.explored),
            ua_final: last.map(|s| s.ua),
            oa_final: last.map(|s| s.oa),
            target_set_area_mean: mean_of(|s| s.target_set_area),
            loc_error_mean_m: mean_of(|s| s.loc_error_m),
            identified_final: last.map(|s| s.identified),
            time_all_identified_s: series
                .iter()
                .find(|(_, s)| targets > 0 && s.identified >= f64::from(targets))
                .map(|(t, _)| *t),
        }
    }

    /// The values of one agent's series.
    pub fn of_agent(series: &[StepMetrics], uav: u32, targets: u32) -> MetricFinals {
        let points = series
            .iter()
            .filter_map(|m| m.agents.get(&uav).map(|s| (m.time_s, s)));
        MetricFinals::of(points, targets)
    }
}

/// Mean and largest value, `None` if any value is.
fn mean_and_max(values: &[Option<f64>]) -> (Option<f64>, Option<f64>) {
    let v: Option<Vec<f64>> = values.iter().copied().collect();
    match v {
        Some(v) if !v.is_empty() => (
            Some(v.iter().sum::<f64>() / v.len() as f64),
            v.iter().copied().reduce(f64::max),
        ),
        _ => (None, None),
    }
}

/// Traffic of one service kind.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CommsSummary {
    /// Messages.
    pub messages: u64,
    /// Bytes (payload and user header).
    pub bytes: u64,
    /// Send-to-receipt latency (kinds that carry a send time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timing: Option<LatencySummary>,
}

/// Latency percentiles, milliseconds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LatencySummary {
    /// Median.
    pub latency_p50_ms: f64,
    /// 90th percentile.
    pub latency_p90_ms: f64,
    /// 99th percentile.
    pub latency_p99_ms: f64,
}

/// The cars' sets the agents held under windows, per agent-step
/// ([`WindowTally`](crate::observe::tally::WindowTally)): how many an agent that kept only the
/// cars whose sets meet its window would keep.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct WindowsSummary {
    /// Agent-steps measured under windows.
    pub agent_steps: u64,
    /// Cars' sets an agent held, mean over those agent-steps.
    pub targets_held_mean: f64,
    /// Of them, the sets with a cell in the agent's window.
    pub targets_meeting_window_mean: f64,
    /// The share of the sets held that met the window (`null` when none was held).
    pub targets_meeting_window_share: Option<f64>,
    /// The share of the cells of the sets held that belong to sets that met the window.
    pub target_cells_meeting_window_share: Option<f64>,
}

impl WindowsSummary {
    /// The summary of `tally`; `None` when no agent-step was measured under a window.
    pub fn of(tally: &crate::observe::tally::WindowTally) -> Option<WindowsSummary> {
        let per_step = |n: u64| n as f64 / tally.agent_steps as f64;
        let share = |part: u64, all: u64| (all > 0).then(|| part as f64 / all as f64);
        (tally.agent_steps > 0).then(|| WindowsSummary {
            agent_steps: tally.agent_steps,
            targets_held_mean: per_step(tally.targets),
            targets_meeting_window_mean: per_step(tally.targets_meeting),
            targets_meeting_window_share: share(tally.targets_meeting, tally.targets),
            target_cells_meeting_window_share: share(
                tally.target_cells_meeting,
                tally.target_cells,
            ),
        })
    }
}

/// Messages the observer dropped and steps it could not measure.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ObserverSummary {
    /// Steps for which no estimate arrived.
    pub steps_without_estimates: u64,
    /// Messages dropped, by reason.
    pub dropped: BTreeMap<String, u64>,
}

/// Run-specific values (wall clock, ids).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RunTiming {
    /// The run id.
    pub run_id: String,
    /// Start of the run, UTC.
    pub started_utc: String,
    /// Wall time from the first truth to the last step acknowledged, seconds.
    pub stepping_s: Option<f64>,
    /// Iceoryx2 files of the run left after cleanup (should be 0).
    pub leftover_ipc_files: usize,
}

/// What the summary needs of a run: what it was, what the observer measured, the faults and
/// how it ended.
#[derive(Clone, Copy, Debug)]
pub struct RunFacts<'a> {
    /// The scenario run.
    pub scenario: &'a Scenario,
    /// The guidance variant's name.
    pub variant: &'static str,
    /// `lockstep` or `realtime`.
    pub mode: &'static str,
    /// The `--chaos` seed, if one was given.
    pub chaos_seed: Option<u64>,
    /// Hosts the fleet ran on.
    pub hosts: u16,
    /// The run id.
    pub run_id: &'a str,
    /// The metrics of every measured step, in order.
    pub series: &'a [StepMetrics],
    /// What the observer gathered (`None` if its thread failed).
    pub observer: Option<&'a ObserverReport>,
    /// The faults and what became of them.
    pub faults: &'a [FaultRecord],
    /// Wall time of the whole run, seconds.
    pub wall_s: f64,
    /// Whether the run was interrupted or failed.
    pub interrupted: bool,
    /// Start of the run, UTC.
    pub started_utc: &'a str,
    /// The run's iceoryx2 files still present after cleanup.
    pub leftover_files: usize,
    /// CPU time, peak memory and phases per process.
    pub resources: &'a Resources,
}

/// The first time the step's mean over agents of UA was below `fraction`, seconds.
fn first_ua_below(series: &[StepMetrics], fraction: f64) -> Option<f64> {
    series
        .iter()
        .find(|m| m.mean.is_some_and(|s| s.ua < fraction))
        .map(|m| m.time_s)
}

impl Summary {
    /// Summarises a run.
    pub fn build(record: &RunFacts<'_>) -> Summary {
        let scenario = record.scenario;
        let series = record.series;
        let all = scenario.targets.count;
        let finals = FleetFinals::of(series, scenario.uavs.count, all);
        let (resync_steps_max, resync_steps_mean) = faults::resync_max_mean(record.faults);
        let steps = series.len() as u64;
        let sim_s = steps as f64 * scenario.timing.cvs_period_s;
        let observer = record.observer;
        let agents = agent_summaries(record, &finals.per_agent);
        let comms = comms_summaries(observer);
        let FleetFinals {
            mean,
            worst,
            last,
            time_all_identified_s,
            time_all_identified_s_worst,
            time_all_identified_any_s,
            ..
        } = finals;
        Summary {
            seed: scenario.seed,
            variant: record.variant.to_owned(),
            uavs: scenario.uavs.count,
            targets: all,
            mode: record.mode.to_owned(),
            duration_s: scenario.duration_s,
            sim_s,
            wall_s: record.wall_s,
            real_time_factor: if record.wall_s > 0.0 {
                sim_s / record.wall_s
            } else {
                0.0
            },
            steps,
            interrupted: record.interrupted,
            violations: series.iter().map(|m| u64::from(m.violations)).sum(),
            explored_final: mean.explored_final,
            ua_final: mean.ua_final,
            oa_final: mean.oa_final,
            target_set_area_mean: mean.target_set_area_mean,
            loc_error_mean_m: mean.loc_error_mean_m,
            identified_final: mean.identified_final.unwrap_or_default(),
            time_all_identified_s,
            time_ua_below_25_s: first_ua_below(series, 0.25),
            time_ua_below_15_s: first_ua_below(series, 0.15),
            explored_final_worst: worst.explored_final,
            ua_final_worst: worst.ua_final,
            oa_final_worst: worst.oa_final,
            target_set_area_mean_worst: worst.target_set_area_mean,
            loc_error_mean_m_worst: worst.loc_error_mean_m,
            identified_final_worst: worst.identified_final.unwrap_or_default(),
            time_all_identified_s_worst,
            identified_any_final: last.map_or(0, |m| m.identified_any),
            time_all_identified_any_s,
            faults: record.faults.to_vec(),
            chaos_seed: record.chaos_seed,
            hosts: record.hosts,
            resync_steps_max,
            resync_steps_mean,
            geofence_overrides: agents.iter().map(|a| a.geofence_overrides).sum(),
            windows: observer.and_then(|o| WindowsSummary::of(&o.windows)),
            agents,
            comms,
            observer: ObserverSummary {
                steps_without_estimates: series.iter().filter(|m| m.mean.is_none()).count() as u64,
                dropped: observer.map(|o| o.dropped.clone()).unwrap_or_default(),
            },
            resources: record.resources.clone(),
            timing: RunTiming {
                run_id: record.run_id.to_owned(),
                started_utc: record.started_utc.to_owned(),
                stepping_s: observer.and_then(|o| o.stepping).map(|d| d.as_secs_f64()),
                leftover_ipc_files: record.leftover_files,
            },
        }
    }

    /// Writes the summary as pretty JSON.
    pub fn write_json(&self, path: &std::path::Path) -> anyhow::Result<()> {
        let mut text = serde_json::to_string_pretty(self)?;
        text.push('\n');
        std::fs::write(path, text)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
    }

    /// Prints the summary as a table.
    pub fn print_table(&self, out: &mut impl Write) -> std::io::Result<()> {
        let rows = self.table_rows();
        let width = rows.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
        for (k, v) in &rows {
            writeln!(out, "  {k:<width$}  {v}")?;
        }
        if !self.agents.is_empty() {
            writeln!(out)?;
            print_agents(&self.agents, out)?;
        }
        print_resources(&self.resources, out)
    }

    /// The rows of the table's first part: the run, the set metrics and, when there were
    /// any, the faults.
    fn table_rows(&self) -> Vec<(&'static str, String)> {
        let opt = |v: Option<f64>, digits: usize| {
            v.map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"))
        };
        let spread = |mean: Option<f64>, worst: Option<f64>, digits: usize| {
            format!("{}  ({})", opt(mean, digits), opt(worst, digits))
        };
        let mut rows: Vec<(&str, String)> = vec![
            ("seed", self.seed.to_string()),
            ("variant", self.variant.to_owned()),
            (
                "UAVs / targets",
                format!("{} / {}", self.uavs, self.targets),
            ),
            (
                "steps (sim s)",
                format!("{} ({:.1} s)", self.steps, self.sim_s),
            ),
            ("wall time", format!("{:.1} s", self.wall_s)),
            ("real-time factor", format!("{:.2}", self.real_time_factor)),
            ("violations", self.violations.to_string()),
            (
                "identified by any (final)",
                format!("{} / {}", self.identified_any_final, self.targets),
            ),
            ("set metrics", "mean over agents  (worst agent)".to_owned()),
            (
                "explored (final)",
                spread(self.explored_final, self.explored_final_worst, 4),
            ),
            ("UA (final)", spread(self.ua_final, self.ua_final_worst, 4)),
            ("OA (final)", spread(self.oa_final, self.oa_final_worst, 4)),
            (
                "target-set area (mean)",
                spread(
                    self.target_set_area_mean,
                    self.target_set_area_mean_worst,
                    5,
                ),
            ),
            (
                "loc. error (mean, m)",
                spread(self.loc_error_mean_m, self.loc_error_mean_m_worst, 2),
            ),
            (
                "identified (final)",
                format!(
                    "{:.2}  ({}) / {}",
                    self.identified_final, self.identified_final_worst, self.targets
                ),
            ),
            (
                "all identified at (s)",
                spread(
                    self.time_all_identified_s,
                    self.time_all_identified_s_worst,
                    1,
                ),
            ),
            ("interrupted", self.interrupted.to_string()),
        ];
        if !self.faults.is_empty() {
            let effective = self.faults.iter().filter(|f| f.effective).count();
            rows.push((
                "faults (effective)",
                format!("{} ({effective})", self.faults.len()),
            ));
            rows.push((
                "resync, steps (mean, worst)",
                format!(
                    "{}  ({})",
                    opt(self.resync_steps_mean, 1),
                    self.resync_steps_max
                        .map_or_else(|| "-".to_owned(), |v| v.to_string())
                ),
            ));
        }
        rows
    }
}

/// The set metrics of the fleet over the run: the mean over agents, the worst agent, each
/// agent's own, and when all targets were first identified.
struct FleetFinals<'a> {
    /// The per-step mean over agents.
    mean: MetricFinals,
    /// The per-step worst agent.
    worst: MetricFinals,
    /// Each agent's own, by UAV.
    per_agent: BTreeMap<u32, MetricFinals>,
    /// The last measured step.
    last: Option<&'a StepMetrics>,
    /// Mean over the agents of the last measured step of the time each first held every
    /// target.
    time_all_identified_s: Option<f64>,
    /// The slowest of those agents' times.
    time_all_identified_s_worst: Option<f64>,
    /// First time every target was identified by some agent.
    time_all_identified_any_s: Option<f64>,
}

impl<'a> FleetFinals<'a> {
    /// The finals of `series`, in a fleet of `uavs` and a world of `targets`.
    fn of(series: &'a [StepMetrics], uavs: u32, targets: u32) -> FleetFinals<'a> {
        let mean = MetricFinals::of(
            series
                .iter()
                .filter_map(|m| m.mean.as_ref().map(|s| (m.time_s, s))),
            targets,
        );
        let worst = MetricFinals::of(
            series
                .iter()
                .filter_map(|m| m.worst.as_ref().map(|s| (m.time_s, s))),
            targets,
        );
        let per_agent: BTreeMap<u32, MetricFinals> = (0..uavs)
            .map(|uav| (uav, MetricFinals::of_agent(series, uav, targets)))
            .collect();
        let last = series.iter().rev().find(|m| m.mean.is_some());
        // The agents of the end of the run, each at its own first time.
        let times: Vec<Option<f64>> = last
            .map(|m| {
                m.agents
                    .keys()
                    .map(|uav| per_agent.get(uav).and_then(|f| f.time_all_identified_s))
                    .collect()
            })
            .unwrap_or_default();
        let (time_all_identified_s, time_all_identified_s_worst) = mean_and_max(&times);
        let time_all_identified_any_s = series
            .iter()
            .find(|m| targets > 0 && m.identified_any >= targets)
            .map(|m| m.time_s);
        FleetFinals {
            mean,
            worst,
            per_agent,
            last,
            time_all_identified_s,
            time_all_identified_s_worst,
            time_all_identified_any_s,
        }
    }
}

/// One summary per UAV of the scenario, from what the observer counted and the faults.
fn agent_summaries(
    record: &RunFacts<'_>,
    per_agent: &BTreeMap<u32, MetricFinals>,
) -> Vec<AgentSummary> {
    let observer = record.observer;
    (0..record.scenario.uavs.count)
        .map(|uav| {
            let t = observer.and_then(|o| o.agents.get(&uav));
            let last = observer.and_then(|o| o.final_undetected.get(&uav));
            let counters = t.map(AgentTally::counters).unwrap_or_default();
            AgentSummary {
                estimates_sent: t.map_or(0, AgentTally::estimates_sent),
                estimates_observed: t.map_or(0, |t| t.estimates_seen),
                final_undetected_digest: last.map(|(_, set)| set.digest()),
                final_measured_step: last.map(|(step, _)| *step),
                restarts: faults::restarts(record.faults, uav),
                geofence_overrides: observer
                    .and_then(|o| o.geofence_overrides.get(uav as usize))
                    .copied()
                    .unwrap_or(0),
                metrics: per_agent.get(&uav).cloned().unwrap_or_default(),
                ..AgentSummary::of_counters(uav, counters)
            }
        })
        .collect()
}

/// The traffic per service kind, with the latency of the kinds that carry a send time.
fn comms_summaries(observer: Option<&ObserverReport>) -> BTreeMap<String, CommsSummary> {
    observer
        .map(|o| {
            o.comms
                .by_kind
                .iter()
                .map(|(kind, t)| {
                    let timing = (matches!(kind, ServiceKind::Estimates | ServiceKind::Tokens))
                        .then(|| Stats::from_samples(&t.latencies_ms))
                        .flatten()
                        .map(|s| LatencySummary {
                            latency_p50_ms: s.median,
                            latency_p90_ms: s.p90,
                            latency_p99_ms: s.p99,
                        });
                    let summary = CommsSummary {
                        messages: t.messages,
                        bytes: t.bytes,
                        timing,
                    };
                    (kind.key().to_owned(), summary)
                })
                .collect()
        })
        .unwrap_or_default()
}

/// The agents' table: one line per agent, with what the radio lost when a link was lossy.
fn print_agents(agents: &[AgentSummary], out: &mut impl Write) -> std::io::Result<()> {
    // Lossy links (`comms.loss`): what the radio lost on the way to each agent.
    let lossy = agents.iter().any(|a| a.estimates_lost + a.tokens_lost > 0);
    write!(
        out,
        "  {:>3}  {:>6}  {:>6}  {:>8}  {:>9}  {:>8}",
        "UAV", "steps", "sent", "received", "decisions", "restarts"
    )?;
    if lossy {
        write!(out, "  {:>15}", "lost est./tok.")?;
    }
    writeln!(out)?;
    for a in agents {
        write!(
            out,
            "  {:>3}  {:>6}  {:>6}  {:>8}  {:>9}  {:>8}",
            a.uav,
            a.steps_processed,
            a.estimates_sent,
            a.estimates_received,
            a.decisions,
            a.restarts
        )?;
        if lossy {
            let lost = format!("{}/{}", a.estimates_lost, a.tokens_lost);
            write!(out, "  {lost:>15}")?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// The resources table: one line per process (CPU, peak memory, phases by CPU time, the
/// waits by wall time), then the totals.
fn print_resources(r: &Resources, out: &mut impl Write) -> std::io::Result<()> {
    if r.processes.is_empty() {
        return Ok(());
    }
    let opt = |v: Option<f64>, digits: usize| {
        v.map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"))
    };
    writeln!(out)?;
    writeln!(
        out,
        "  {:<14} {:>7} {:>7}  phases, CPU s  | waits, wall s",
        "process", "CPU s", "peak MB"
    )?;
    for p in &r.processes {
        let name = match (p.uav, p.incarnation) {
            (Some(uav), Some(n)) if n > 1 => format!("agent {uav} #{n}"),
            (Some(uav), _) => format!("agent {uav}"),
            _ => p.role.to_owned(),
        };
        let is_wait = |name: &str| name.contains("wait");
        let mut busy: Vec<(&String, &f64)> = p.phases.iter().filter(|(n, _)| !is_wait(n)).collect();
        busy.sort_by(|a, b| b.1.total_cmp(a.1));
        let busy: Vec<String> = busy
            .iter()
            .filter(|(_, s)| **s >= 0.005)
            .map(|(n, s)| format!("{n} {s:.2}"))
            .collect();
        let waits: Vec<String> = p
            .phases_wall_s
            .iter()
            .filter(|(n, _)| is_wait(n))
            .map(|(n, s)| format!("{n} {s:.1}"))
            .collect();
        let phases = if busy.is_empty() && waits.is_empty() {
            "-".to_owned()
        } else {
            format!("{}  | {}", busy.join(", "), waits.join(", "))
        };
        writeln!(
            out,
            "  {:<14} {:>7} {:>7}  {phases}",
            name,
            opt(p.cpu_s, 2),
            opt(p.peak_rss_mb, 0),
        )?;
    }
    let t = &r.totals;
    writeln!(
        out,
        "  CPU {:.1} s in all ({:.1} s world and agents, {} ms per UAV step); {} wall s per \
         simulated s",
        t.cpu_s,
        t.world_and_agents_cpu_s,
        opt(t.cpu_ms_per_uav_step, 1),
        opt(t.wall_s_per_sim_s, 3),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observe::metrics::SetMetrics;

    #[test]
    fn an_agents_counters_fill_their_keys_of_the_summary_in_order() {
        let counters = AgentStats {
            frames: 1,
            frames_refused: 2,
            estimates_received: 3,
            messages_dropped: 4,
            decisions: 5,
            token_timeouts: 6,
            estimates_lost: 7,
            tokens_lost: 8,
            relayed_applied: 9,
            relayed_sent: 10,
            external_decisions: 11,
            external_fallbacks: 12,
        };
        let json = serde_json::to_string(&AgentSummary::of_counters(3, counters))
            .expect("a summary prints");
        let expected = concat!(
            r#"{"uav":3,"steps_processed":1,"estimates_sent":0,"estimates_received":3,"#,
            r#""estimates_observed":0,"messages_dropped":4,"decisions":5,"token_timeouts":6,"#,
            r#""estimates_lost":7,"tokens_lost":8,"relayed_applied":9,"relayed_sent":10,"#,
            r#""external_decisions":11,"external_fallbacks":12,"final_undetected_digest":null,"#,
            r#""final_measured_step":null,"restarts":0,"geofence_overrides":0,"metrics":{"#,
        );
        assert!(json.starts_with(expected), "{json}");
    }

    #[test]
    fn ua_falls_below_a_fraction_at_the_first_step_whose_mean_is_below() {
        let step = |time_s: f64, ua: Option<f64>| StepMetrics {
            time_s,
            mean: ua.map(|ua| SetMetrics {
                ua,
                ..SetMetrics::default()
            }),
            ..StepMetrics::default()
        };
        let series = [
            step(0.5, Some(0.9)),
            step(1.0, None),
            step(1.5, Some(0.2)),
            step(2.0, Some(0.1)),
            step(2.5, Some(0.3)),
        ];
        assert_eq!(first_ua_below(&series, 0.25), Some(1.5));
        assert_eq!(first_ua_below(&series, 0.15), Some(2.0));
        assert_eq!(first_ua_below(&series, 0.05), None);
        assert_eq!(first_ua_below(&[], 0.25), None);
    }
}
