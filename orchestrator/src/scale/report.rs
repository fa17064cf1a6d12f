//! The rows of `fleet bench scale` (one per run, a series and a fleet size, [`ScaleRow`]) and
//! the report they make: a [`BenchReport`] of kind `scale` with one case per run (named
//! `"<series key> uavs=<N>"`, [`Series::key`]: `measurements uavs=16`, `measurements_wauto
//! uavs=16`), the goals and, per series, the headline figures at the top
//! (`real_time_factor_16_<key>`, `bytes_per_uav_ratio_16_<key>`,
//! `cpu_per_uav_step_ratio_16_<key>`, `agent_peak_mb_16_<key>`).
//!
//! A run's ratios ([`set_ratios`]) are against the [`REFERENCE_UAVS`]-UAV run **of the same
//! series** (exchange and window): each series is its own scaling curve, another's 4-UAV run
//! is never the reference.
//!
//! Rates are per second of **simulated** time, so they do not depend on the machine's speed.
//! Messages and bytes are those the observer received from the estimates' and the token's
//! services: each message once, as published (a peer's copy is the same shared-memory sample).
//! CPU is every process's (orchestrator, world-server, agents), from the run's `resources`.

use std::collections::BTreeMap;
use std::io::Write;

use serde_json::{Value, json};

use super::{REFERENCE_UAVS, ScaleConfig, ScalePoint, Series};
use crate::run::RunRecord;
use fleet_bench::{BenchCase, BenchReport, Metrics};
use fleet_observe::results::resources::ProcessResources;
use fleet_observe::results::summary::{Summary, WindowsSummary};

/// The goal: real-time factor of a 16-UAV fleet (on 2 cores).
pub const GOAL_RTF_16: f64 = 2.0;
/// The goal: bytes per UAV per second at 16 UAVs over the 4-UAV figure.
pub const GOAL_BYTES_RATIO_16: f64 = 1.5;
/// The goal: CPU per UAV-step at 16 UAVs over the 4-UAV figure.
pub const GOAL_CPU_RATIO_16: f64 = 1.5;
/// The goal: peak resident memory of the largest agent at 16 UAVs, MB.
pub const GOAL_AGENT_PEAK_MB_16: f64 = 60.0;

/// How a run ended.
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

/// One run, a series and a fleet size: what it measured.
#[derive(Clone, Debug, PartialEq)]
pub struct ScaleRow {
    /// The exchange (`comms.exchange`) and the window (`estimator.window_m`) as asked.
    pub series: Series,
    /// UAVs.
    pub uavs: u32,
    /// The window's half-side (the run's `estimator.window_m`), metres; `None` for the whole
    /// region.
    pub window_m: Option<f64>,
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
    /// The cars' sets the agents held under windows and those that met their window.
    pub windows: Option<WindowsSummary>,
    /// Bytes per UAV per second over the same figure at [`REFERENCE_UAVS`] UAVs in the same
    /// series (set by [`set_ratios`]).
    pub bytes_per_uav_ratio_to_4: Option<f64>,
    /// CPU per UAV-step over the same figure at [`REFERENCE_UAVS`] UAVs in the same series
    /// (set by [`set_ratios`]).
    pub cpu_per_uav_step_ratio_to_4: Option<f64>,
}

impl ScaleRow {
    fn empty(point: &ScalePoint, status: RowStatus) -> ScaleRow {
        ScaleRow {
            series: point.series,
            uavs: point.uavs,
            window_m: point.window_m(),
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
            windows: None,
            bytes_per_uav_ratio_to_4: None,
            cpu_per_uav_step_ratio_to_4: None,
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
            windows: summary.windows.clone(),
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

    /// The line `fleet bench scale` prints when the run is done.
    pub fn progress_line(&self) -> String {
        let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or_else(|| "-".into(), f);
        format!(
            "{}, {} UAVs, {} cars, {:.0} m: {}, real time x{}, CPU {} ms per UAV-step, {} B per \
             UAV per s, agent peak {} MB, {} violations",
            self.series.label(),
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

    /// The row as a report case: the series, the sizes and the status as parameters
    /// (`window` as asked, `inf`, `auto` or metres, and `window_m` as run, `null` for the
    /// whole region), every measured value as a metric (a value not measured is left out).
    pub fn to_case(&self) -> BenchCase {
        let mut params = BTreeMap::new();
        params.insert("exchange".into(), json!(self.series.exchange.name()));
        params.insert("window".into(), json!(self.series.window.to_string()));
        params.insert("window_m".into(), json!(self.window_m));
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
        put(
            "cpu_per_uav_step_ratio_to_4",
            self.cpu_per_uav_step_ratio_to_4,
        );
        put("peak_rss_mb_world", self.memory.world_mb);
        put("peak_rss_mb_agent_max", self.memory.agent_max_mb);
        put("peak_rss_mb_agents_sum", self.memory.agents_sum_mb);
        put("peak_rss_mb_orchestrator", self.memory.orchestrator_mb);
        if let Some(w) = &self.windows {
            put("targets_held_mean", Some(w.targets_held_mean));
            put(
                "targets_meeting_window_mean",
                Some(w.targets_meeting_window_mean),
            );
            put(
                "targets_meeting_window_share",
                w.targets_meeting_window_share,
            );
            put(
                "target_cells_meeting_window_share",
                w.target_cells_meeting_window_share,
            );
        }
        put("violations", Some(self.violations as f64));
        put(
            "leftover_ipc_files",
            self.leftover_ipc_files.map(|n| n as f64),
        );
        BenchCase {
            name: format!("{} uavs={}", self.series.key(), self.uavs),
            params,
            metrics: m,
        }
    }
}

/// The run of `series` with `uavs` UAVs that went well.
fn good_run(rows: &[ScaleRow], series: Series, uavs: u32) -> Option<&ScaleRow> {
    rows.iter()
        .find(|r| r.series == series && r.uavs == uavs && r.status == RowStatus::Ok)
}

/// Sets every row's bytes per UAV per second and CPU per UAV-step over the
/// [`REFERENCE_UAVS`]-UAV row's of the same series (none without that row or its figure).
pub fn set_ratios(rows: &mut [ScaleRow]) {
    let ratios: Vec<(Option<f64>, Option<f64>)> = rows
        .iter()
        .map(|row| {
            let reference = good_run(rows, row.series, REFERENCE_UAVS);
            let ratio = |f: &dyn Fn(&ScaleRow) -> Option<f64>| {
                let base = reference.and_then(f).filter(|b| *b > 0.0)?;
                Some(f(row)? / base)
            };
            (
                ratio(&ScaleRow::bytes_per_uav_s),
                ratio(&|r| r.cpu_ms_per_uav_step),
            )
        })
        .collect();
    for (row, (bytes, cpu)) in rows.iter_mut().zip(ratios) {
        row.bytes_per_uav_ratio_to_4 = bytes;
        row.cpu_per_uav_step_ratio_to_4 = cpu;
    }
}

/// The report: the goals, the exchanges and the series and, per series, the headline figures
/// of its 16-UAV run (real-time factor, bytes and CPU ratios, largest agent's peak memory;
/// `null` without a good 16-UAV run), one case per row.
pub fn build(config: &ScaleConfig, rows: &[ScaleRow]) -> BenchReport {
    let mut report = BenchReport::new("scale");
    let s = &mut report.summary;
    s.insert("seed".into(), json!(config.seed));
    s.insert("duration_s".into(), json!(config.duration_s));
    s.insert("variant".into(), json!(config.variant.name()));
    s.insert("mode".into(), json!("lockstep"));
    let names: Vec<&str> = config.exchanges.iter().map(|&e| e.name()).collect();
    s.insert("exchanges".into(), json!(names));
    let keys: Vec<String> = config.series.iter().map(Series::key).collect();
    s.insert("series".into(), json!(keys));
    s.insert("reference_uavs".into(), json!(REFERENCE_UAVS));
    s.insert("goal_uavs".into(), json!(16));
    s.insert("goal_real_time_factor".into(), json!(GOAL_RTF_16));
    s.insert("goal_cores".into(), json!(2));
    s.insert(
        "goal_bytes_per_uav_ratio".into(),
        json!(GOAL_BYTES_RATIO_16),
    );
    s.insert(
        "goal_cpu_per_uav_step_ratio".into(),
        json!(GOAL_CPU_RATIO_16),
    );
    s.insert("goal_agent_peak_mb".into(), json!(GOAL_AGENT_PEAK_MB_16));
    let number = |v: Option<f64>| {
        v.filter(|v| v.is_finite())
            .map_or(Value::Null, |v| json!(v))
    };
    for &series in &config.series {
        let name = series.key();
        let at_16 = good_run(rows, series, 16);
        let headline: [(&str, Option<f64>); 4] = [
            (
                "real_time_factor_16",
                at_16.and_then(ScaleRow::real_time_factor),
            ),
            (
                "bytes_per_uav_ratio_16",
                at_16.and_then(|r| r.bytes_per_uav_ratio_to_4),
            ),
            (
                "cpu_per_uav_step_ratio_16",
                at_16.and_then(|r| r.cpu_per_uav_step_ratio_to_4),
            ),
            (
                "agent_peak_mb_16",
                at_16.and_then(|r| r.memory.agent_max_mb),
            ),
        ];
        for (key, value) in headline {
            s.insert(format!("{key}_{name}"), number(value));
        }
    }
    s.insert(
        "violations".into(),
        json!(rows.iter().map(|r| r.violations).sum::<u64>()),
    );
    let failed: Vec<String> = rows
        .iter()
        .filter(|r| !r.is_clean())
        .map(|r| format!("{} uavs={}: {}", r.series.key(), r.uavs, r.status.text()))
        .collect();
    s.insert("failed_runs".into(), json!(failed));
    report.cases = rows.iter().map(ScaleRow::to_case).collect();
    report
}

/// Prints the headline columns, one line per run.
pub fn print_table(rows: &[ScaleRow], out: &mut impl Write) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<20} {:>5} {:>7} {:>5} {:>7} {:>9} {:>12} {:>9} {:>12} {:>7} {:>10} {:>10} {:>4}  \
         status",
        "series",
        "UAVs",
        "side m",
        "cars",
        "steps",
        "RTF",
        "CPU ms/UAV",
        "CPU vs 4",
        "B/UAV/s",
        "B vs 4",
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
            "{:<20} {:>5} {:>7.0} {:>5} {:>7} {:>9} {:>12} {:>9} {:>12} {:>7} {:>10} {:>10} {:>4}  \
             {}",
            r.series.key(),
            r.uavs,
            r.region_side_m,
            r.cars,
            r.steps,
            cell(r.real_time_factor(), 2),
            cell(r.cpu_ms_per_uav_step, 2),
            cell(r.cpu_per_uav_step_ratio_to_4, 2),
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
    use crate::scale::WindowChoice;
    use protocol::scenario::Exchange;
    use protocol::variant::Variant;
    use std::path::PathBuf;

    /// A row of `uavs` under `exchange` that ran 10 simulated s, with `estimate_bytes_per_s`
    /// bytes of estimates per second and `cpu_ms` per UAV-step.
    fn row(exchange: Exchange, uavs: u32, estimate_bytes_per_s: f64, cpu_ms: f64) -> ScaleRow {
        ScaleRow {
            series: Series {
                exchange,
                window: WindowChoice::Whole,
            },
            uavs,
            window_m: None,
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
            cpu_ms_per_uav_step: Some(cpu_ms),
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
            windows: None,
            bytes_per_uav_ratio_to_4: None,
            cpu_per_uav_step_ratio_to_4: None,
        }
    }

    fn sets(uavs: u32, bytes: f64, cpu_ms: f64) -> ScaleRow {
        row(Exchange::Sets, uavs, bytes, cpu_ms)
    }

    fn measurements(uavs: u32, bytes: f64, cpu_ms: f64) -> ScaleRow {
        row(Exchange::Measurements, uavs, bytes, cpu_ms)
    }

    fn ratios(rows: &[ScaleRow]) -> Vec<(Option<f64>, Option<f64>)> {
        rows.iter()
            .map(|r| (r.bytes_per_uav_ratio_to_4, r.cpu_per_uav_step_ratio_to_4))
            .collect()
    }

    /// `row` in a series with a window of `window_m`.
    fn windowed(mut row: ScaleRow, window_m: f64) -> ScaleRow {
        row.series.window = WindowChoice::Metres(window_m);
        row.window_m = Some(window_m);
        row
    }

    fn config(series: Vec<Series>) -> ScaleConfig {
        ScaleConfig {
            points: Vec::new(),
            exchanges: crate::scale::each_once(series.iter().map(|s| s.exchange)),
            series,
            seed: 1,
            duration_s: 10.0,
            variant: Variant::Paper,
            out: PathBuf::from("o"),
            runs: PathBuf::from("o/runs"),
        }
    }

    #[test]
    fn ratios_are_per_uav_against_the_four_uav_row_of_the_same_exchange() {
        let mut rows = vec![
            sets(2, 200.0, 50.0),
            sets(4, 800.0, 100.0),
            sets(8, 4800.0, 300.0),
            measurements(2, 100.0, 40.0),
            measurements(4, 400.0, 80.0),
            measurements(8, 800.0, 120.0),
        ];
        set_ratios(&mut rows);
        // Sets: 100, 200 and 600 bytes per UAV per second; measurements: 50, 100 and 100.
        assert_eq!(
            ratios(&rows),
            vec![
                (Some(0.5), Some(0.5)),
                (Some(1.0), Some(1.0)),
                (Some(3.0), Some(3.0)),
                (Some(0.5), Some(0.5)),
                (Some(1.0), Some(1.0)),
                (Some(1.0), Some(1.5)),
            ]
        );
        let mut without = vec![sets(2, 200.0, 50.0), sets(8, 800.0, 100.0)];
        set_ratios(&mut without);
        assert!(ratios(&without).iter().all(|r| *r == (None, None)));
    }

    #[test]
    fn the_other_exchanges_four_uav_row_is_never_the_reference() {
        // Only the sets have a 4-UAV row: the measurements' rows have no ratio.
        let mut rows = vec![
            sets(4, 800.0, 100.0),
            sets(8, 1600.0, 200.0),
            measurements(2, 100.0, 40.0),
            measurements(8, 800.0, 120.0),
        ];
        set_ratios(&mut rows);
        assert_eq!(
            ratios(&rows),
            vec![
                (Some(1.0), Some(1.0)),
                (Some(1.0), Some(2.0)),
                (None, None),
                (None, None),
            ]
        );
        // Nor when its own 4-UAV run failed.
        let mut failed = measurements(4, 400.0, 80.0);
        failed.status = RowStatus::Failed("the world-server exited".into());
        let mut rows = vec![sets(4, 800.0, 100.0), failed, measurements(8, 800.0, 120.0)];
        set_ratios(&mut rows);
        assert_eq!(ratios(&rows)[2], (None, None));
    }

    #[test]
    fn a_windowed_series_is_against_its_own_four_uav_run() {
        let mut rows = vec![
            measurements(4, 400.0, 80.0),
            measurements(16, 1600.0, 200.0),
            windowed(measurements(4, 400.0, 100.0), 320.0),
            windowed(measurements(16, 1600.0, 120.0), 320.0),
            windowed(measurements(16, 1600.0, 110.0), 150.0),
        ];
        set_ratios(&mut rows);
        assert_eq!(
            ratios(&rows),
            vec![
                (Some(1.0), Some(1.0)),
                (Some(1.0), Some(2.5)),
                (Some(1.0), Some(1.0)),
                (Some(1.0), Some(1.2)),
                // No 4-UAV run with a 150 m window.
                (None, None),
            ]
        );
        let case = rows[3].to_case();
        assert_eq!(case.name, "measurements_w320 uavs=16");
        assert_eq!(case.params["window"], "320");
        assert_eq!(case.params["window_m"], 320.0);
        assert_eq!(rows[0].to_case().params["window_m"], Value::Null);
        assert_eq!(case.metrics.get("targets_meeting_window_share"), None);
        rows[3].windows = Some(WindowsSummary {
            agent_steps: 40,
            targets_held_mean: 8.0,
            targets_meeting_window_mean: 2.0,
            targets_meeting_window_share: Some(0.25),
            target_cells_meeting_window_share: Some(0.5),
        });
        let case = rows[3].to_case();
        for (key, value) in [
            ("targets_held_mean", 8.0),
            ("targets_meeting_window_mean", 2.0),
            ("targets_meeting_window_share", 0.25),
            ("target_cells_meeting_window_share", 0.5),
        ] {
            assert_eq!(case.metrics.get(key), Some(value), "{key}");
        }
        assert!(
            rows[3]
                .progress_line()
                .starts_with("measurements, 320 m window, 16 UAVs")
        );
        let series: Vec<Series> = rows[..3].iter().map(|r| r.series).collect();
        let report = build(&config(series[1..].to_vec()), &rows);
        let s = &report.summary;
        assert_eq!(s["exchanges"], json!(["measurements"]));
        assert_eq!(s["series"], json!(["measurements", "measurements_w320"]));
        assert_eq!(s["cpu_per_uav_step_ratio_16_measurements"], 2.5);
        assert_eq!(s["cpu_per_uav_step_ratio_16_measurements_w320"], 1.2);
    }

    #[test]
    fn a_case_carries_every_measure_and_a_failed_row_only_its_status() {
        let mut rows = vec![sets(4, 800.0, 100.0)];
        set_ratios(&mut rows);
        let case = rows[0].to_case();
        assert_eq!(case.name, "sets uavs=4");
        assert_eq!(case.params["status"], "ok");
        assert_eq!(case.params["exchange"], "sets");
        for (key, value) in [
            ("real_time_factor", 2.0),
            ("cpu_ms_per_uav_step", 100.0),
            ("estimates_msgs_per_uav_s", 2.0),
            ("estimates_bytes_per_uav_s", 200.0),
            ("tokens_msgs_per_s", 1.0),
            ("msgs_per_s", 9.0),
            ("bytes_per_uav_s", 200.0),
            ("bytes_per_uav_ratio_to_4", 1.0),
            ("cpu_per_uav_step_ratio_to_4", 1.0),
            ("peak_rss_mb_agents_sum", 120.0),
            ("violations", 0.0),
        ] {
            assert_eq!(case.metrics.get(key), Some(value), "{key}");
        }
        assert_eq!(
            measurements(16, 0.0, 1.0).to_case().name,
            "measurements uavs=16"
        );
        let mut failed = sets(16, 0.0, 100.0);
        failed.status = RowStatus::Failed("the world-server exited".into());
        assert!(!failed.is_clean());
        let line = failed.progress_line();
        assert!(line.starts_with("sets, 16 UAVs"), "{line}");
        assert!(line.contains("failed: the world-server exited"), "{line}");
        let mut violated = sets(1, 0.0, 100.0);
        violated.violations = 2;
        assert!(!violated.is_clean());
        assert!(rows[0].is_clean());
    }

    #[test]
    fn the_summary_has_the_headline_figures_of_each_exchange() {
        let mut failed = measurements(2, 100.0, 40.0);
        failed.status = RowStatus::Interrupted;
        let mut rows = vec![
            sets(4, 800.0, 100.0),
            sets(16, 6400.0, 250.0),
            measurements(4, 400.0, 80.0),
            measurements(16, 1600.0, 80.0),
            failed,
        ];
        rows[1].memory.agent_max_mb = Some(400.0);
        rows[3].memory.agent_max_mb = Some(55.0);
        set_ratios(&mut rows);
        let report = build(&config(vec![rows[0].series, rows[2].series]), &rows);
        let s = &report.summary;
        assert_eq!(s["exchanges"], json!(["sets", "measurements"]));
        assert_eq!(s["series"], json!(["sets", "measurements"]));
        assert_eq!(s["goal_cpu_per_uav_step_ratio"], 1.5);
        assert_eq!(s["goal_agent_peak_mb"], 60.0);
        assert_eq!(s["goal_bytes_per_uav_ratio"], 1.5);
        for (key, value) in [
            ("real_time_factor_16_sets", 2.0),
            ("bytes_per_uav_ratio_16_sets", 2.0),
            ("cpu_per_uav_step_ratio_16_sets", 2.5),
            ("agent_peak_mb_16_sets", 400.0),
            ("real_time_factor_16_measurements", 2.0),
            ("bytes_per_uav_ratio_16_measurements", 1.0),
            ("cpu_per_uav_step_ratio_16_measurements", 1.0),
            ("agent_peak_mb_16_measurements", 55.0),
        ] {
            assert_eq!(s[key], value, "{key}");
        }
        assert!(!s.contains_key("real_time_factor_16"));
        assert_eq!(
            s["failed_runs"],
            json!(["measurements uavs=2: interrupted"])
        );
        assert_eq!(report.cases.len(), 5);
        // Without a 16-UAV run, the headline figures are null.
        let report = build(&config(vec![rows[2].series]), &rows[..1]);
        assert_eq!(report.summary["exchanges"], json!(["measurements"]));
        assert_eq!(
            report.summary["real_time_factor_16_measurements"],
            Value::Null
        );
    }

    #[test]
    fn the_table_has_a_line_per_run_with_its_series() {
        let mut rows = vec![
            sets(4, 800.0, 100.0),
            measurements(4, 400.0, 80.0),
            windowed(measurements(4, 400.0, 80.0), 150.0),
        ];
        set_ratios(&mut rows);
        let mut out = Vec::new();
        print_table(&rows, &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        assert!(lines[0].starts_with("series"), "{text}");
        assert!(lines[0].contains("CPU vs 4"), "{text}");
        assert!(lines[1].starts_with("sets "), "{text}");
        assert!(lines[2].starts_with("measurements "), "{text}");
        assert!(lines[3].starts_with("measurements_w150 "), "{text}");
    }
}
