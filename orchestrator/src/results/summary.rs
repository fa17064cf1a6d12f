//! `summary.json`: the run's final metrics, faults, agents and traffic (DESIGN.md §7).
//!
//! Two runs of the same scenario and seed in lockstep give byte-identical summaries except
//! for what depends on the wall clock, which lives only under keys named `wall_s`,
//! `real_time_factor` and `timing` (at any depth), so a comparison can drop them. Maps are
//! ordered; floats are written as computed.

use std::collections::BTreeMap;
use std::io::Write;

use serde::Serialize;

use crate::bench::Stats;
use crate::observe::tally::ServiceKind;
use crate::run::RunRecord;
use crate::run::faults::FaultRecord;

/// The summary of a run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// Scenario seed.
    pub seed: u64,
    /// The guidance variant (`paper`, `kappa0`, `nomap`, `setfleet`).
    pub variant: &'static str,
    /// UAVs in the fleet.
    pub uavs: u32,
    /// Targets in the world.
    pub targets: u32,
    /// `lockstep` or `realtime`.
    pub mode: &'static str,
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
    /// Explored ground at the last measured step, fraction of the region.
    pub explored_final: Option<f64>,
    /// UA (undetected area) at the last measured step, fraction of the region.
    pub ua_final: Option<f64>,
    /// OA (undetected area in occluded ground) at the last measured step, fraction.
    pub oa_final: Option<f64>,
    /// Mean target-set area over the steps with at least one identified target, fraction.
    pub target_set_area_mean: Option<f64>,
    /// Mean localisation error over the steps with at least one identified target, metres.
    pub loc_error_mean_m: Option<f64>,
    /// Targets identified at the last measured step.
    pub identified_final: u32,
    /// First time every target was identified, seconds (`null` if never).
    pub time_all_identified_s: Option<f64>,
    /// Faults injected.
    pub faults: Vec<FaultRecord>,
    /// Per agent.
    pub agents: Vec<AgentSummary>,
    /// Traffic per service kind.
    pub comms: BTreeMap<&'static str, CommsSummary>,
    /// What the observer could not use.
    pub observer: ObserverSummary,
    /// Values that differ between two runs of the same scenario and seed.
    pub timing: RunTiming,
}

/// One agent over the run (summed over its incarnations).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
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
    /// Restarts injected.
    pub restarts: u64,
}

/// Traffic of one service kind.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
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
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LatencySummary {
    /// Median.
    pub latency_p50_ms: f64,
    /// 90th percentile.
    pub latency_p90_ms: f64,
    /// 99th percentile.
    pub latency_p99_ms: f64,
}

/// Messages the observer dropped and steps it could not measure.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ObserverSummary {
    /// Steps for which no estimate arrived.
    pub steps_without_estimates: u64,
    /// Messages dropped, by reason.
    pub dropped: BTreeMap<String, u64>,
}

/// Run-specific values (wall clock, ids).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
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

impl Summary {
    /// Summarises a run.
    pub fn build(record: &RunRecord) -> Summary {
        let scenario = &record.config.scenario;
        let series = &record.series;
        let measured: Vec<_> = series
            .iter()
            .filter_map(|m| m.sets.map(|s| (m, s)))
            .collect();
        let last = measured.last().map(|(_, s)| *s);
        let mean_of = |f: &dyn Fn(&crate::observe::metrics::SetMetrics) -> Option<f64>| {
            let v: Vec<f64> = measured
                .iter()
                .filter(|(_, s)| s.identified > 0)
                .filter_map(|(_, s)| f(s))
                .collect();
            (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
        };
        let all = scenario.targets.count;
        let time_all_identified_s = measured
            .iter()
            .find(|(_, s)| all > 0 && s.identified >= all)
            .map(|(m, _)| m.time_s);
        let steps = series.len() as u64;
        let sim_s = steps as f64 * scenario.timing.cvs_period_s;
        let observer = record.observer.as_ref();
        let agents = (0..scenario.uavs.count)
            .map(|uav| {
                let t = observer.and_then(|o| o.agents.get(&uav));
                AgentSummary {
                    uav,
                    steps_processed: t.map_or(0, |t| t.steps_processed()),
                    estimates_sent: t.map_or(0, |t| t.estimates_sent()),
                    estimates_received: t.map_or(0, |t| t.estimates_received()),
                    estimates_observed: t.map_or(0, |t| t.estimates_seen),
                    messages_dropped: t.map_or(0, |t| t.messages_dropped()),
                    decisions: t.map_or(0, |t| t.decisions()),
                    token_timeouts: t.map_or(0, |t| t.token_timeouts()),
                    restarts: record.faults.restarts(uav),
                }
            })
            .collect();
        let comms = observer
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
                        (kind.key(), summary)
                    })
                    .collect()
            })
            .unwrap_or_default();
        Summary {
            seed: scenario.seed,
            variant: record.config.variant.name(),
            uavs: scenario.uavs.count,
            targets: all,
            mode: match record.config.mode {
                world_server::server::StepMode::Lockstep => "lockstep",
                world_server::server::StepMode::Realtime { .. } => "realtime",
            },
            duration_s: scenario.duration_s,
            sim_s,
            wall_s: record.wall_s,
            real_time_factor: if record.wall_s > 0.0 {
                sim_s / record.wall_s
            } else {
                0.0
            },
            steps,
            interrupted: record.interrupted || record.failure.is_some(),
            violations: record.violations(),
            explored_final: last.map(|s| s.explored),
            ua_final: last.map(|s| s.ua),
            oa_final: last.map(|s| s.oa),
            target_set_area_mean: mean_of(&|s| s.target_set_area),
            loc_error_mean_m: mean_of(&|s| s.loc_error_m),
            identified_final: last.map_or(0, |s| s.identified),
            time_all_identified_s,
            faults: record.faults.records().to_vec(),
            agents,
            comms,
            observer: ObserverSummary {
                steps_without_estimates: series.iter().filter(|m| m.sets.is_none()).count() as u64,
                dropped: observer.map(|o| o.dropped.clone()).unwrap_or_default(),
            },
            timing: RunTiming {
                run_id: record.config.run_id.to_string(),
                started_utc: record.started_utc.clone(),
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
        let opt = |v: Option<f64>, digits: usize| {
            v.map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"))
        };
        let rows: Vec<(&str, String)> = vec![
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
            ("explored (final)", opt(self.explored_final, 4)),
            ("UA (final)", opt(self.ua_final, 4)),
            ("OA (final)", opt(self.oa_final, 4)),
            ("target-set area (mean)", opt(self.target_set_area_mean, 5)),
            ("loc. error (mean, m)", opt(self.loc_error_mean_m, 2)),
            (
                "identified (final)",
                format!("{} / {}", self.identified_final, self.targets),
            ),
            (
                "all identified at",
                self.time_all_identified_s
                    .map_or_else(|| "never".to_owned(), |t| format!("{t:.1} s")),
            ),
            ("interrupted", self.interrupted.to_string()),
        ];
        let width = rows.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
        for (k, v) in &rows {
            writeln!(out, "  {k:<width$}  {v}")?;
        }
        if !self.agents.is_empty() {
            writeln!(out)?;
            writeln!(
                out,
                "  {:>3}  {:>6}  {:>6}  {:>8}  {:>9}  {:>8}",
                "UAV", "steps", "sent", "received", "decisions", "restarts"
            )?;
            for a in &self.agents {
                writeln!(
                    out,
                    "  {:>3}  {:>6}  {:>6}  {:>8}  {:>9}  {:>8}",
                    a.uav,
                    a.steps_processed,
                    a.estimates_sent,
                    a.estimates_received,
                    a.decisions,
                    a.restarts
                )?;
            }
        }
        Ok(())
    }
}
