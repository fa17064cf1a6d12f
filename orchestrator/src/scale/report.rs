//! The rows of `fleet bench scale` (one per fleet size, [`ScaleRow`]) and the report they make:
//! a [`BenchReport`] of kind `scale` with one case per fleet size, the goals and the headline
//! figures at the top.
//!
//! Rates are per second of **simulated** time, so they do not depend on the machine's speed.
//! Messages and bytes are those the observer received from the estimates' and the token's
//! services: each message once, as published (a peer's copy is the same shared-memory sample).
//! CPU is every process's (orchestrator, world-server, agents), from the run's `resources`.

use std::collections::BTreeMap;
use std::io::Write;

use serde_json::{Value, json};

use super::{REFERENCE_UAVS, ScaleConfig, ScalePoint};
use crate::run::RunRecord;
use fleet_bench::{BenchCase, BenchReport, Metrics};
use fleet_observe::results::resources::ProcessResources;
use fleet_observe::results::summary::Summary;

/// The goal: real-time factor of a 16-UAV fleet (on 2 cores).
pub const GOAL_RTF_16: f64 = 2.0;
/// The goal: bytes per UAV per second at 16 UAVs over the 4-UAV figure.
pub const GOAL_BYTES_RATIO_16: f64 = 1.5;

/// How a fleet size's run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum RowStatus {
    /// It ran to its end and its results are written.
    Ok,
    /// It ran, but its results could not be written.
    ResultsNotWritten,
    /// A signal cut it short.
    Interrupted,
    /// It failed: why.
    Failed(String),
}

impl RowStatus {
    /// The status as written in the JSON.
    pub fn text(&self) -> String {
        match self {
            RowStatus::Ok => "ok".into(),
            RowStatus::ResultsNotWritten => "results not written".into(),
            RowStatus::Interrupted => "interrupted".into(),
            RowStatus::Failed(why) => format!("failed: {why}"),
        }
    }
}

/// Traffic of one service kind per simulated second.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rates {
    /// Messages per second, whole fleet.
    pub msgs_per_s: f64,
    /// Bytes per second, whole fleet.
    pub bytes_per_s: f64,
}

impl Rates {
    fn of(summary: &Summary, key: &str, sim_s: f64) -> Option<Rates> {
        let c = summary.comms.get(key);
        (sim_s > 0.0).then(|| Rates {
            msgs_per_s: c.map_or(0.0, |c| c.messages as f64) / sim_s,
            bytes_per_s: c.map_or(0.0, |c| c.bytes as f64) / sim_s,
        })
    }
}

/// Peak resident memory, MB.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PeakMemory {
    /// The world-server.
    pub world_mb: Option<f64>,
    /// The largest agent process.
    pub agent_max_mb: Option<f64>,
    /// All agent processes together (each at its own peak).
    pub agents_sum_mb: Option<f64>,
    /// The orchestrator: its peak since it started, so over every smaller fleet before too.
    pub orchestrator_mb: Option<f64>,
}

impl PeakMemory {
    fn of(processes: &[ProcessResources]) -> PeakMemory {
        let of_role = |role: &'static str| {
            processes
                .iter()
                .filter(move |p| p.role == role)
                .filter_map(|p| p.peak_rss_mb)
        };
        let agents: Vec<f64> = of_role("agent").collect();
        PeakMemory {
            world_mb: of_role("world").reduce(f64::max),
            agent_max_mb: agents.iter().copied().reduce(f64::max),
            agents_sum_mb: (!agents.is_empty()).then(|| agents.iter().sum()),
            orchestrator_mb: of_role("orchestrator").reduce(f64::max),
        }
    }
}

/// One fleet size: what its run measured.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleRow {
    /// UAVs.
    pub uavs: u32,
    /// Side of the square region, metres.
    pub region_side_m: f64,
    /// Cars.
    pub cars: u32,
    /// How the run ended.
    pub status: RowStatus,
    /// The run's directory.
    pub run_dir: String,
    /// Steps measured.
    pub steps: u64,
    /// Simulated seconds.
    pub sim_s: f64,
    /// Wall time of the whole run (start-up and shutdown included), seconds.
    pub wall_s: f64,
    /// Wall seconds per simulated second, whole run.
    pub wall_s_per_sim_s: Option<f64>,
    /// Wall seconds per simulated second while stepping (from the first truth to the last
    /// step), without start-up and shutdown.
    pub stepping_wall_s_per_sim_s: Option<f64>,
    /// CPU seconds of every process.
    pub cpu_s: Option<f64>,
    /// Every process's CPU over UAVs x steps, milliseconds.
    pub cpu_ms_per_uav_step: Option<f64>,
    /// The world's and agents' CPU over UAVs x steps, milliseconds.
    pub world_and_agents_cpu_ms_per_uav_step: Option<f64>,
    /// Estimates.
    pub estimates: Option<Rates>,
    /// The guidance token.
    pub tokens: Option<Rates>,
    /// Peak memory.
    pub memory: PeakMemory,
    /// Guarantee violations (must be 0).
    pub violations: u64,
    /// The run's iceoryx2 files left after it (must be 0).
    pub leftover_ipc_files: Option<usize>,
    /// Bytes per UAV per second over the same figure at [`REFERENCE_UAVS`] UAVs (set by
    /// [`set_ratios`]).
    pub bytes_per_uav_ratio_to_4: Option<f64>,
}

impl ScaleRow {
    fn empty(point: &ScalePoint, status: RowStatus) -> ScaleRow {
        ScaleRow {
            uavs: point.uavs,
            region_side_m: 2.0 * point.half_extent_m(),
            cars: point.cars(),
            status,
            run_dir: point.config.out.display().to_string(),
            steps: 0,
            sim_s: 0.0,
            wall_s: 0.0,
            wall_s_per_sim_s: None,
            stepping_wall_s_per_sim_s: None,
            cpu_s: None,
            cpu_ms_per_uav_step: None,
            world_and_agents_cpu_ms_per_uav_step: None,
            estimates: None,
            tokens: None,
            memory: PeakMemory::default(),
            violations: 0,
            leftover_ipc_files: None,
            bytes_per_uav_ratio_to_4: None,
        }
    }

    /// A run that could not run at all.
    pub fn failed(point: &ScalePoint, why: String) -> ScaleRow {
        ScaleRow::empty(point, RowStatus::Failed(why))
    }

    /// The row of a run that ran (to its end or not); `written` says whether its results
    /// were written.
    pub fn of_run(
        point: &ScalePoint,
        record: &RunRecord,
        summary: &Summary,
        written: bool,
    ) -> ScaleRow {
        let status = if let Some(why) = &record.failure {
            RowStatus::Failed(why.clone())
        } else if record.interrupted {
            RowStatus::Interrupted
        } else if !written {
            RowStatus::ResultsNotWritten
        } else {
            RowStatus::Ok
        };
        let sim_s = summary.sim_s;
        let uav_steps = f64::from(summary.uavs) * summary.steps as f64;
        let totals = &summary.resources.totals;
        let per_uav_step = |cpu_s: f64| (uav_steps > 0.0).then(|| cpu_s * 1e3 / uav_steps);
        ScaleRow {
            steps: summary.steps,
            sim_s,
            wall_s: summary.wall_s,
            wall_s_per_sim_s: (sim_s > 0.0).then(|| summary.wall_s / sim_s),
            stepping_wall_s_per_sim_s: summary
                .timing
                .stepping_s
                .filter(|_| sim_s > 0.0)
                .map(|s| s / sim_s),
            cpu_s: Some(totals.cpu_s),
            cpu_ms_per_uav_step: per_uav_step(totals.cpu_s),
            world_and_agents_cpu_ms_per_uav_step: per_uav_step(totals.world_and_agents_cpu_s),
            estimates: Rates::of(summary, "estimates", sim_s),
            tokens: Rates::of(summary, "tokens", sim_s),
            memory: PeakMemory::of(&summary.resources.processes),
            violations: summary.violations,
            leftover_ipc_files: Some(record.leftover_files),
            ..ScaleRow::empty(point, status)
        }
    }

    /// Simulated seconds per wall second, whole run.
    pub fn real_time_factor(&self) -> Option<f64> {
        self.wall_s_per_sim_s.filter(|w| *w > 0.0).map(|w| 1.0 / w)
    }

    /// Estimates' and token's bytes per UAV per simulated second.
    pub fn bytes_per_uav_s(&self) -> Option<f64> {
        let (e, t) = (self.estimates?, self.tokens?);
        Some((e.bytes_per_s + t.bytes_per_s) / f64::from(self.uavs))
    }

    /// Whether the run went well: ran to its end, no violation, nothing left behind.
    pub fn is_clean(&self) -> bool {
        self.status == RowStatus::Ok
            && self.violations == 0
            && self.leftover_ipc_files.is_some_and(|n| n == 0)
    }

    /// The line `fleet bench scale` prints when the size is done.
    pub fn progress_line(&self) -> String {
        let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or_else(|| "-".into(), f);
        format!(
            "{} UAVs, {} cars, {:.0} m: {}, real time x{}, CPU {} ms per UAV-step, {} B per UAV \
             per s, agent peak {} MB, {} violations",
            self.uavs,
            self.cars,
            self.region_side_m,
            self.status.text(),
            opt(self.real_time_factor(), &|v| format!("{v:.2}")),
            opt(self.cpu_ms_per_uav_step, &|v| format!("{v:.2}")),
            opt(self.bytes_per_uav_s(), &|v| format!("{v:.0}")),
            opt(self.memory.agent_max_mb, &|v| format!("{v:.0}")),
            self.violations,
        )
    }

    /// The row as a report case: the sizes and the status as parameters, every measured
    /// value as a metric (a value not measured is left out).
    pub fn to_case(&self) -> BenchCase {
        let mut params = BTreeMap::new();
        params.insert("uavs".into(), json!(self.uavs));
        params.insert("region_side_m".into(), json!(self.region_side_m));
        params.insert("cars".into(), json!(self.cars));
        params.insert("status".into(), json!(self.status.text()));
        params.insert("run_dir".into(), json!(self.run_dir));
        let mut m = Metrics::default();
        let mut put = |name: &str, v: Option<f64>| {
            if let Some(v) = v.filter(|v| v.is_finite()) {
                m.push(name, v);
            }
        };
        put("steps", Some(self.steps as f64));
        put("sim_s", Some(self.sim_s));
        put("wall_s", Some(self.wall_s));
        put("wall_s_per_sim_s", self.wall_s_per_sim_s);
        put("real_time_factor", self.real_time_factor());
        put("stepping_wall_s_per_sim_s", self.stepping_wall_s_per_sim_s);
        put("cpu_s", self.cpu_s);
        put("cpu_ms_per_uav_step", self.cpu_ms_per_uav_step);
        put(
            "world_and_agents_cpu_ms_per_uav_step",
            self.world_and_agents_cpu_ms_per_uav_step,
        );
        let uavs = f64::from(self.uavs);
        for (kind, rates) in [("estimates", self.estimates), ("tokens", self.tokens)] {
            put(&format!("{kind}_msgs_per_s"), rates.map(|r| r.msgs_per_s));
            put(&format!("{kind}_bytes_per_s"), rates.map(|r| r.bytes_per_s));
            put(
                &format!("{kind}_msgs_per_uav_s"),
                rates.map(|r| r.msgs_per_s / uavs),
            );
            put(
                &format!("{kind}_bytes_per_uav_s"),
                rates.map(|r| r.bytes_per_s / uavs),
            );
        }
        let both = self.estimates.zip(self.tokens);
        put("msgs_per_s", both.map(|(e, t)| e.msgs_per_s + t.msgs_per_s));
        put(
            "bytes_per_s",
            both.map(|(e, t)| e.bytes_per_s + t.bytes_per_s),
        );
        put(
            "msgs_per_uav_s",
            both.map(|(e, t)| (e.msgs_per_s + t.msgs_per_s) / uavs),
        );
        put("bytes_per_uav_s", self.bytes_per_uav_s());
        put("bytes_per_uav_ratio_to_4", self.bytes_per_uav_ratio_to_4);
        put("peak_rss_mb_world", self.memory.world_mb);
        put("peak_rss_mb_agent_max", self.memory.agent_max_mb);
        put("peak_rss_mb_agents_sum", self.memory.agents_sum_mb);
        put("peak_rss_mb_orchestrator", self.memory.orchestrator_mb);
        put("violations", Some(self.violations as f64));
        put(
            "leftover_ipc_files",
            self.leftover_ipc_files.map(|n| n as f64),
        );
        BenchCase {
            name: format!("uavs={}", self.uavs),
            params,
            metrics: m,
        }
    }
}

/// Sets every row's bytes per UAV per second over the [`REFERENCE_UAVS`]-UAV row's (none
/// without that row or its figure).
pub fn set_ratios(rows: &mut [ScaleRow]) {
    let reference = rows
        .iter()
        .find(|r| r.uavs == REFERENCE_UAVS && r.status == RowStatus::Ok)
        .and_then(ScaleRow::bytes_per_uav_s)
        .filter(|b| *b > 0.0);
    for row in rows {
        row.bytes_per_uav_ratio_to_4 = reference.and_then(|r| Some(row.bytes_per_uav_s()? / r));
    }
}

/// The report: the goals and the headline figures (the largest fleet's real-time factor and
/// bytes ratio), one case per row.
pub fn build(config: &ScaleConfig, rows: &[ScaleRow]) -> BenchReport {
    let mut report = BenchReport::new("scale");
    let s = &mut report.summary;
    s.insert("seed".into(), json!(config.seed));
    s.insert("duration_s".into(), json!(config.duration_s));
    s.insert("variant".into(), json!(config.variant.name()));
    s.insert("mode".into(), json!("lockstep"));
    s.insert("reference_uavs".into(), json!(REFERENCE_UAVS));
    s.insert("goal_uavs".into(), json!(16));
    s.insert("goal_real_time_factor".into(), json!(GOAL_RTF_16));
    s.insert("goal_cores".into(), json!(2));
    s.insert(
        "goal_bytes_per_uav_ratio".into(),
        json!(GOAL_BYTES_RATIO_16),
    );
    let at_16 = rows
        .iter()
        .find(|r| r.uavs == 16 && r.status == RowStatus::Ok);
    let number = |v: Option<f64>| {
        v.filter(|v| v.is_finite())
            .map_or(Value::Null, |v| json!(v))
    };
    s.insert(
        "real_time_factor_16".into(),
        number(at_16.and_then(ScaleRow::real_time_factor)),
    );
    s.insert(
        "bytes_per_uav_ratio_16".into(),
        number(at_16.and_then(|r| r.bytes_per_uav_ratio_to_4)),
    );
    s.insert(
        "violations".into(),
        json!(rows.iter().map(|r| r.violations).sum::<u64>()),
    );
    let failed: Vec<String> = rows
        .iter()
        .filter(|r| !r.is_clean())
        .map(|r| format!("uavs={}: {}", r.uavs, r.status.text()))
        .collect();
    s.insert("failed_runs".into(), json!(failed));
    report.cases = rows.iter().map(ScaleRow::to_case).collect();
    report
}

/// Prints the headline columns, one line per fleet size.
pub fn print_table(rows: &[ScaleRow], out: &mut impl Write) -> std::io::Result<()> {
    writeln!(
        out,
        "{:>5} {:>7} {:>5} {:>7} {:>9} {:>12} {:>12} {:>7} {:>10} {:>10} {:>4}  status",
        "UAVs",
        "side m",
        "cars",
        "steps",
        "RTF",
        "CPU ms/UAV",
        "B/UAV/s",
        "vs 4",
        "agent MB",
        "agents MB",
        "viol"
    )?;
    let cell = |v: Option<f64>, digits: usize| {
        v.filter(|v| v.is_finite())
            .map_or_else(|| "-".to_owned(), |v| format!("{v:.digits$}"))
    };
    for r in rows {
        writeln!(
            out,
            "{:>5} {:>7.0} {:>5} {:>7} {:>9} {:>12} {:>12} {:>7} {:>10} {:>10} {:>4}  {}",
            r.uavs,
            r.region_side_m,
            r.cars,
            r.steps,
            cell(r.real_time_factor(), 2),
            cell(r.cpu_ms_per_uav_step, 2),
            cell(r.bytes_per_uav_s(), 0),
            cell(r.bytes_per_uav_ratio_to_4, 2),
            cell(r.memory.agent_max_mb, 0),
            cell(r.memory.agents_sum_mb, 0),
            r.violations,
            r.status.text()
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row of `uavs` that ran, with `bytes` per second of estimates over 10 simulated s.
    fn row(uavs: u32, estimate_bytes_per_s: f64) -> ScaleRow {
        ScaleRow {
            uavs,
            region_side_m: 100.0,
            cars: 1,
            status: RowStatus::Ok,
            run_dir: "d".into(),
            steps: 20,
            sim_s: 10.0,
            wall_s: 5.0,
            wall_s_per_sim_s: Some(0.5),
            stepping_wall_s_per_sim_s: Some(0.4),
            cpu_s: Some(4.0),
            cpu_ms_per_uav_step: Some(100.0),
            world_and_agents_cpu_ms_per_uav_step: Some(90.0),
            estimates: Some(Rates {
                msgs_per_s: 2.0 * f64::from(uavs),
                bytes_per_s: estimate_bytes_per_s,
            }),
            tokens: Some(Rates {
                msgs_per_s: 1.0,
                bytes_per_s: 0.0,
            }),
            memory: PeakMemory {
                world_mb: Some(50.0),
                agent_max_mb: Some(30.0),
                agents_sum_mb: Some(30.0 * f64::from(uavs)),
                orchestrator_mb: Some(20.0),
            },
            violations: 0,
            leftover_ipc_files: Some(0),
            bytes_per_uav_ratio_to_4: None,
        }
    }

    #[test]
    fn bytes_ratios_are_per_uav_against_the_four_uav_row() {
        let mut rows = vec![row(2, 200.0), row(4, 800.0), row(8, 4800.0)];
        set_ratios(&mut rows);
        let ratios: Vec<Option<f64>> = rows.iter().map(|r| r.bytes_per_uav_ratio_to_4).collect();
        // 100, 200 and 600 bytes per UAV per second.
        assert_eq!(ratios, vec![Some(0.5), Some(1.0), Some(3.0)]);
        let mut without = vec![row(2, 200.0), row(8, 800.0)];
        set_ratios(&mut without);
        assert!(without.iter().all(|r| r.bytes_per_uav_ratio_to_4.is_none()));
    }

    #[test]
    fn a_case_carries_every_measure_and_a_failed_row_only_its_status() {
        let mut rows = vec![row(4, 800.0)];
        set_ratios(&mut rows);
        let case = rows[0].to_case();
        assert_eq!(case.name, "uavs=4");
        assert_eq!(case.params["status"], "ok");
        for (key, value) in [
            ("real_time_factor", 2.0),
            ("cpu_ms_per_uav_step", 100.0),
            ("estimates_msgs_per_uav_s", 2.0),
            ("estimates_bytes_per_uav_s", 200.0),
            ("tokens_msgs_per_s", 1.0),
            ("msgs_per_s", 9.0),
            ("bytes_per_uav_s", 200.0),
            ("bytes_per_uav_ratio_to_4", 1.0),
            ("peak_rss_mb_agents_sum", 120.0),
            ("violations", 0.0),
        ] {
            assert_eq!(case.metrics.get(key), Some(value), "{key}");
        }
        let mut failed = row(16, 0.0);
        failed.status = RowStatus::Failed("the world-server exited".into());
        assert!(!failed.is_clean());
        assert!(
            failed
                .progress_line()
                .contains("failed: the world-server exited")
        );
        let mut violated = row(1, 0.0);
        violated.violations = 2;
        assert!(!violated.is_clean());
        assert!(rows[0].is_clean());
    }
}
