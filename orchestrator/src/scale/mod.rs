//! `fleet bench scale`: how the whole system scales with the fleet, under each way the agents
//! exchange what they know. It runs real fleets, the same code path as `fleet run`
//! ([`execute`], lockstep, one seed), of 1, 2, 4, 8 and 16 UAVs by default ([`DEFAULT_UAVS`];
//! `--uavs 1,2,4,8,16,32,64` adds the larger fleets, up to the protocol's [`MAX_UAVS`]), each
//! under every exchange of `--exchange` (`comms.exchange`: `sets` and `measurements` by
//! default), each over a region scaled so that the **area per UAV** and the **cars per area**
//! stay those of the scenario's, read as a fleet of [`REFERENCE_UAVS`] UAVs
//! ([`scaled_region`]): the region's side scales with `sqrt(n / 4)`, the cars with `n / 4`
//! (rounded, at least 1 if the scenario has any). On the default scenario (4 UAVs, 8 cars,
//! 500 x 500 m):
//!
//! | UAVs | 1 | 2 | 4 | 8 | 16 | 32 | 64 |
//! |---|---:|---:|---:|---:|---:|---:|---:|
//! | region side | 250 m | 354 m | 500 m | 707 m | 1000 m | 1414 m | 2000 m |
//! | cars | 2 | 4 | 8 | 16 | 32 | 64 | 128 |
//!
//! A camera higher up sees more ground, so the fleets also keep the altitude band of the
//! reference fleet ([`altitude_step`]): with automatic altitudes (`uavs.altitudes_m = []`), a
//! fleet larger than [`REFERENCE_UAVS`] flies between the same lowest and highest altitudes
//! as 4 UAVs do (30 m apart by default), its `uavs.altitude_step_m` shrunk to
//! `step x 3 / (n - 1)`: 4.29 m for 8 UAVs, 2 m for 16, 0.48 m for 64. With one step of
//! [`ALTITUDE_STEP_M`] per UAV, the last of 16 would fly 150 m above the first and see
//! several times its ground, and the bench would compare altitudes as much as fleet sizes.
//!
//! Each exchange also runs under every window of `--window-m` (`estimator.window_m`: `inf`,
//! the whole region, by default; a half-side in metres; or `auto`, each fleet's guidance
//! reach, [`Scenario::guidance_reach_m`]): an exchange and a window make a [`Series`], one
//! scaling curve.
//!
//! Per run, one (series, fleet size) pair ([`report::ScaleRow`]): wall time per simulated
//! second and the real-time factor, CPU per UAV-step (every process's CPU over UAVs x steps),
//! the estimates' and the token's messages and bytes per simulated second in total and per
//! UAV, peak resident memory per process (world, largest agent, all agents, orchestrator),
//! violations, and the bytes per UAV per second and the CPU per UAV-step against the 4-UAV
//! run **of the same series**. Writes `scale.json` (a [`BenchReport`], one case per run,
//! the headline figures per series) and `scale.png` ([`plot`], one line per series) into
//! `--out`, each run's own results under `--runs` in `<series key>/uavs-<N>`
//! ([`Series::key`]: `measurements`, `measurements_w300`, `measurements_wauto`).
//!
//! The runs go one after another: for each exchange in the order given, each window in the
//! order given, the fleet sizes smallest first. A run needs the machine to itself for its
//! real-time factor to mean anything. The exchange and the window are the last overrides of
//! each run's scenario, so `--exchange` and `--window-m` win over a `--set comms.exchange=...`
//! or `--set estimator.window_m=...`. A run that fails is a row with its status, the next runs
//! still go (a signal stops the bench), and the exit code is 1.
//!
//! [`BenchReport`]: fleet_bench::BenchReport
//! [`ALTITUDE_STEP_M`]: protocol::scenario::ALTITUDE_STEP_M

pub mod plot;
pub mod report;
pub mod series;

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use clap::builder::PossibleValuesParser;
use protocol::scenario::{Exchange, Scenario};
use protocol::wire::MAX_UAVS;
use world_server::server::StepMode;

use crate::outcome::Outcome;

use crate::run::config::{RunConfig, default_out_dir, new_run_id};
use crate::run::hosts::HostLayout;
use crate::run::{execute, runtime, write_results};
use fleet_process::usage::{ScenarioArgs, UsageError};
use protocol::variant::Variant;
use report::{RowStatus, ScaleRow};
pub use series::{Series, WindowChoice};

/// The fleet size the scenario's region and cars are for.
pub const REFERENCE_UAVS: u32 = 4;

/// The fleet sizes measured by default.
pub const DEFAULT_UAVS: [u32; 5] = [1, 2, 4, 8, 16];

/// `fleet bench scale`.
#[derive(Debug, Clone, Args)]
pub struct BenchScaleArgs {
    /// The scenario: its region and cars are those of a 4-UAV fleet (default: the paper's).
    #[command(flatten)]
    pub scenario: ScenarioArgs,
    /// The guidance variant (applied after the scenario file and before `--set`).
    #[arg(long, value_enum, default_value_t = Variant::Paper)]
    pub variant: Variant,
    /// The seed of every run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Seconds of simulated time per run.
    #[arg(long, default_value_t = 20.0)]
    pub duration: f64,
    /// Fleet sizes, comma-separated (run smallest first), each at most the protocol's largest
    /// fleet (64): `1,2,4,8,16,32,64` adds the large fleets to the default sizes.
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_UAVS.to_vec())]
    pub uavs: Vec<u32>,
    /// The exchanges (`comms.exchange`) to measure, comma-separated, in the order they run;
    /// every fleet size runs under each (overrides `--set comms.exchange=...`).
    #[arg(
        long,
        value_name = "LIST",
        value_delimiter = ',',
        value_parser = PossibleValuesParser::new(Exchange::NAMES),
        default_values = Exchange::NAMES
    )]
    pub exchange: Vec<String>,
    /// The windows (`estimator.window_m`) to measure, comma-separated, in the order they run:
    /// each `inf` (the whole region), a half-side in metres, or `auto` (each fleet's guidance
    /// reach); every exchange runs under each (overrides `--set estimator.window_m=...`).
    #[arg(
        long,
        value_name = "LIST",
        value_delimiter = ',',
        default_value = "inf"
    )]
    pub window_m: Vec<WindowChoice>,
    /// Where `scale.json` and `scale.png` go (default: `runs/scale-<UTC timestamp>`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Where each run's directory (`<exchange>/uavs-<N>`) goes (default: `<out>/runs`).
    #[arg(long)]
    pub runs: Option<PathBuf>,
}

/// One run of the bench, a series and a fleet size, its scenario resolved.
#[derive(Debug, Clone)]
pub struct ScalePoint {
    /// The exchange and the window.
    pub series: Series,
    /// UAVs.
    pub uavs: u32,
    /// The run.
    pub config: RunConfig,
}

impl ScalePoint {
    /// Half the side of the region, metres.
    pub fn half_extent_m(&self) -> f64 {
        self.config.scenario.region.half_extent_m
    }

    /// Cars.
    pub fn cars(&self) -> u32 {
        self.config.scenario.targets.count
    }

    /// The window's half-side (`estimator.window_m`), metres; `None` for the whole region.
    pub fn window_m(&self) -> Option<f64> {
        Some(self.config.scenario.estimator.window_m).filter(|m| m.is_finite())
    }
}

/// A validated `fleet bench scale`.
#[derive(Debug, Clone)]
pub struct ScaleConfig {
    /// The runs in the order they go: by exchange, then by window, then by increasing fleet
    /// size.
    pub points: Vec<ScalePoint>,
    /// The exchanges measured, in the order they run (no repeats).
    pub exchanges: Vec<Exchange>,
    /// The series measured, in the order they run (no repeats).
    pub series: Vec<Series>,
    /// The seed of every run.
    pub seed: u64,
    /// Simulated seconds per run.
    pub duration_s: f64,
    /// The variant.
    pub variant: Variant,
    /// Where `scale.json` and `scale.png` go.
    pub out: PathBuf,
    /// Where the runs' directories go.
    pub runs: PathBuf,
}

/// The region's half side and the cars of a fleet of `uavs` for a scenario whose
/// `half_extent_m` and `cars` are those of [`REFERENCE_UAVS`] UAVs: the same area per UAV
/// (the side scales with `sqrt(uavs / 4)`) and the same cars per area (`cars x uavs / 4`,
/// rounded, at least 1 when the scenario has cars).
pub fn scaled_region(half_extent_m: f64, cars: u32, uavs: u32) -> (f64, u32) {
    let share = f64::from(uavs) / f64::from(REFERENCE_UAVS);
    let half = half_extent_m * share.sqrt();
    let scaled_cars = if cars == 0 {
        0
    } else {
        // At most MAX_UAVS / 4 = 16 times the scenario's cars: no overflow.
        ((f64::from(cars) * share).round() as u32).max(1)
    };
    (half, scaled_cars)
}

/// The automatic altitude step of a fleet of `uavs` that keeps the band of
/// [`REFERENCE_UAVS`] UAVs flying `step` apart: `step` up to that size, then
/// `step x (REFERENCE_UAVS - 1) / (uavs - 1)`.
pub fn altitude_step(step: f64, uavs: u32) -> f64 {
    if uavs <= REFERENCE_UAVS {
        step
    } else {
        step * f64::from(REFERENCE_UAVS - 1) / f64::from(uavs - 1)
    }
}

/// The items in their order, each at its first place only.
fn each_once<T: PartialEq>(items: impl IntoIterator<Item = T>) -> Vec<T> {
    let mut once = Vec::new();
    for item in items {
        if !once.contains(&item) {
            once.push(item);
        }
    }
    once
}

impl BenchScaleArgs {
    /// Checks the flags and resolves every run's scenario.
    pub fn validate(&self) -> Result<ScaleConfig, UsageError> {
        if self.uavs.is_empty() {
            return Err(UsageError("--uavs: give at least one fleet size".into()));
        }
        if let Some(&bad) = self.uavs.iter().find(|&&n| n == 0 || n as usize > MAX_UAVS) {
            return Err(UsageError(format!(
                "--uavs {bad}: every fleet size must be 1 to {MAX_UAVS}, the largest fleet the \
                 protocol carries"
            )));
        }
        if self.exchange.is_empty() {
            return Err(UsageError(format!(
                "--exchange: give at least one of {}",
                Exchange::NAMES.join(", ")
            )));
        }
        if self.window_m.is_empty() {
            return Err(UsageError(
                "--window-m: give at least one window (inf, auto or metres)".into(),
            ));
        }
        if !(self.duration.is_finite() && self.duration > 0.0) {
            return Err(UsageError(format!(
                "--duration {}: must be a positive number of seconds",
                self.duration
            )));
        }
        let mut sizes = self.uavs.clone();
        sizes.sort_unstable();
        sizes.dedup();
        let exchanges = each_once(self.exchange.iter().map(String::as_str));
        let windows = each_once(self.window_m.iter().copied());
        let mut base_overrides = self.variant.with_user_overrides(&self.scenario.overrides);
        base_overrides.push(format!("seed={}", self.seed));
        base_overrides.push(format!("duration_s={:?}", self.duration));
        let base = ScenarioArgs {
            scenario: self.scenario.scenario.clone(),
            overrides: base_overrides.clone(),
        }
        .load()?;
        let out = self
            .out
            .clone()
            .unwrap_or_else(|| default_out_dir("scale-"));
        let runs = self.runs.clone().unwrap_or_else(|| out.join("runs"));
        let mut runs_of = Vec::with_capacity(exchanges.len() * windows.len() * sizes.len());
        for &name in &exchanges {
            for &window in &windows {
                runs_of.extend(sizes.iter().map(|&uavs| (name, window, uavs)));
            }
        }
        let mut points = Vec::with_capacity(runs_of.len());
        for (index, (name, window, uavs)) in runs_of.into_iter().enumerate() {
            let (half, cars) = scaled_region(base.region.half_extent_m, base.targets.count, uavs);
            let mut overrides = base_overrides.clone();
            overrides.push(format!("uavs.count={uavs}"));
            overrides.push(format!("region.half_extent_m={half:?}"));
            overrides.push(format!("targets.count={cars}"));
            if base.uavs.altitudes_m.is_empty() {
                let step = altitude_step(base.uavs.altitude_step_m, uavs);
                overrides.push(format!("uavs.altitude_step_m={step:?}"));
            }
            // Last, so that the flag wins over a `--set comms.exchange=...`.
            overrides.push(format!("comms.exchange={name}"));
            let mut scenario = Scenario::load(self.scenario.scenario.as_deref(), &overrides)
                .map_err(|e| {
                    UsageError(format!(
                        "--uavs {uavs} --exchange {name}: bad scenario: {e}"
                    ))
                })?;
            // The window last too (it wins over `--set estimator.window_m=...`); `auto` reads
            // the fleet's own scenario. Every choice is in the key's range, (0, inf].
            scenario.estimator.window_m = window.resolve(&scenario);
            let series = Series {
                exchange: scenario.comms.exchange,
                window,
            };
            let out = runs.join(series.key()).join(format!("uavs-{uavs}"));
            let run_id = new_run_id(u32::try_from(index).unwrap_or(u32::MAX));
            points.push(self.point(series, scenario, out, run_id));
        }
        Ok(ScaleConfig {
            exchanges: each_once(points.iter().map(|p| p.series.exchange)),
            series: each_once(points.iter().map(|p| p.series)),
            points,
            seed: self.seed,
            duration_s: self.duration,
            variant: self.variant,
            out,
            runs,
        })
    }

    /// The run of a resolved scenario: lockstep, no faults, its own directory and id.
    fn point(
        &self,
        series: Series,
        scenario: Scenario,
        out: PathBuf,
        run_id: protocol::service::RunId,
    ) -> ScalePoint {
        let uavs = scenario.uavs.count;
        ScalePoint {
            series,
            uavs,
            config: RunConfig {
                scenario,
                mode: StepMode::Lockstep,
                faults: Vec::new(),
                out,
                strict: false,
                run_id,
                // One line per tenth of a run: the bench's own lines stay readable.
                progress_bar: false,
                variant: self.variant,
                chaos_seed: None,
                listen: None,
                tls: None,
                insecure_links: false,
                view: fleet_observe::viewer::ViewConfig::default(),
                layout: HostLayout::single(uavs),
            },
        }
    }
}

/// `fleet bench scale`: runs every (exchange, fleet size) pair in turn, writes `scale.json`
/// and `scale.png`, prints the table. Exit code 1 if a run failed, was interrupted or saw a
/// violation.
pub fn command(config: &ScaleConfig) -> anyhow::Result<Outcome> {
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("cannot create {}", config.out.display()))?;
    let rt = runtime()?;
    let total = config.points.len();
    let mut rows = Vec::with_capacity(total);
    for (i, point) in config.points.iter().enumerate() {
        let side = 2.0 * point.half_extent_m();
        let series = point.series.label();
        // What `auto` came to.
        let window = match (point.series.window, point.window_m()) {
            (WindowChoice::Auto, Some(m)) => format!(" ({m} m)"),
            _ => String::new(),
        };
        eprintln!(
            "fleet: scale {}/{total}: {series}{window}, {} UAVs, {} cars, region {side:.0} x \
             {side:.0} m, {} s simulated",
            i + 1,
            point.uavs,
            point.cars(),
            config.duration_s,
        );
        let label = format!("{series}, {} UAVs", point.uavs);
        let row = match rt.block_on(execute(&point.config, &label)) {
            Ok(record) => {
                // The row is the record's, whether or not the run's files could be written.
                let written = write_results(&record).map(|_| ());
                if let Err(e) = &written {
                    eprintln!("fleet: [{label}] cannot write the run's results: {e:#}");
                }
                ScaleRow::of_run(point, &record, &record.summary(), written.is_ok())
            }
            Err(e) => {
                eprintln!("fleet: [{label}] the run failed: {e:#}");
                ScaleRow::failed(point, format!("{e:#}"))
            }
        };
        eprintln!("fleet: scale {}/{total}: {}", i + 1, row.progress_line());
        let stop = row.status == RowStatus::Interrupted;
        rows.push(row);
        if stop {
            eprintln!("fleet: interrupted: the remaining runs do not run");
            break;
        }
    }
    report::set_ratios(&mut rows);
    let report = report::build(config, &rows);
    let json = config.out.join("scale.json");
    report.write_json(&json)?;
    let png = config.out.join("scale.png");
    plot::draw(&rows, config, &png)?;
    let mut stdout = std::io::stdout().lock();
    report::print_table(&rows, &mut stdout)?;
    use std::io::Write as _;
    writeln!(
        stdout,
        "\nreport in {} and {}, runs in {}",
        json.display(),
        png.display(),
        config.runs.display()
    )?;
    let bad = rows.iter().filter(|r| !r.is_clean()).count();
    if bad > 0 {
        eprintln!(
            "fleet: {bad} of {} runs failed (see scale.json)",
            rows.len()
        );
        return Ok(Outcome::Failed);
    }
    if rows.len() < total {
        return Ok(Outcome::Failed);
    }
    Ok(Outcome::Success)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use protocol::scenario::ALTITUDE_STEP_M;

    #[derive(Parser)]
    struct Wrap {
        #[command(flatten)]
        scale: BenchScaleArgs,
    }

    fn parse(args: &[&str]) -> Result<ScaleConfig, String> {
        Wrap::try_parse_from(["x"].iter().chain(args))
            .map_err(|e| e.to_string())
            .and_then(|w| w.scale.validate().map_err(|e| e.0))
    }

    #[test]
    fn the_region_keeps_the_area_per_uav_and_the_cars_per_area() {
        for (uavs, half, cars) in [
            (1, 125.0, 2),
            (2, 250.0 * 0.5_f64.sqrt(), 4),
            (4, 250.0, 8),
            (8, 250.0 * 2.0_f64.sqrt(), 16),
            (16, 500.0, 32),
            (32, 250.0 * 8.0_f64.sqrt(), 64),
        ] {
            let (h, c) = scaled_region(250.0, 8, uavs);
            assert!((h - half).abs() < 1e-9, "{uavs}: {h}");
            assert_eq!(c, cars, "{uavs}");
            let area_per_uav = (2.0 * h).powi(2) / f64::from(uavs);
            assert!((area_per_uav - 62_500.0).abs() < 1e-6);
        }
        // Rounded, at least one car; none stays none.
        assert_eq!(scaled_region(100.0, 3, 1).1, 1);
        assert_eq!(scaled_region(100.0, 1, 1).1, 1);
        assert_eq!(scaled_region(100.0, 3, 2).1, 2);
        assert_eq!(scaled_region(100.0, 0, 16).1, 0);
    }

    #[test]
    fn every_exchange_name_is_the_one_a_scenario_reads() {
        for name in Exchange::NAMES {
            let s = Scenario::load(None, &[format!("comms.exchange={name}")]).unwrap();
            assert_eq!(s.comms.exchange.name(), name);
        }
    }

    #[test]
    fn fleet_sizes_are_sorted_and_each_gets_its_scenario_and_directory() {
        let c = parse(&[
            "--uavs",
            "8,1,4,1",
            "--exchange",
            "sets",
            "--duration",
            "5",
            "--out",
            "o",
        ])
        .unwrap();
        let sizes: Vec<u32> = c.points.iter().map(|p| p.uavs).collect();
        assert_eq!(sizes, vec![1, 4, 8]);
        assert_eq!(c.exchanges, vec![Exchange::Sets]);
        let four = &c.points[1];
        assert_eq!(four.config.scenario.uavs.count, 4);
        assert_eq!(four.cars(), 8);
        assert_eq!(four.half_extent_m(), 250.0);
        assert_eq!(four.config.scenario.duration_s, 5.0);
        assert_eq!(four.config.scenario.seed, 1);
        assert_eq!(four.config.mode, StepMode::Lockstep);
        assert_eq!(c.points[2].cars(), 16);
        assert_eq!(c.runs, PathBuf::from("o/runs"));
        assert_eq!(c.points[0].config.out, PathBuf::from("o/runs/sets/uavs-1"));
        let c = parse(&["--seed", "5", "--runs", "r", "--set", "targets.count=2"]).unwrap();
        assert_eq!(c.points.len(), 2 * DEFAULT_UAVS.len());
        assert_eq!(c.points[0].config.scenario.seed, 5);
        assert_eq!(c.points[0].config.out, PathBuf::from("r/sets/uavs-1"));
        assert_eq!(c.points[4].cars(), 8);
    }

    #[test]
    fn the_large_fleets_get_the_issues_regions_and_cars() {
        let c = parse(&["--uavs", "1,2,4,8,16,32,64", "--exchange", "measurements"]).unwrap();
        let got: Vec<(u32, f64, u32)> = c
            .points
            .iter()
            .map(|p| (p.uavs, (2.0 * p.half_extent_m()).round(), p.cars()))
            .collect();
        assert_eq!(
            got,
            [
                (1, 250.0, 2),
                (2, 354.0, 4),
                (4, 500.0, 8),
                (8, 707.0, 16),
                (16, 1000.0, 32),
                (32, 1414.0, 64),
                // The largest fleet the protocol carries: 2 x 2 km, 128 cars.
                (64, 2000.0, 128),
            ]
        );
        // Every fleet flies within the 4-UAV fleet's band: 30 m from the lowest to the highest.
        for p in &c.points {
            let s = &p.config.scenario;
            let n = s.uavs.count as usize;
            let band = s.uav_altitude(n - 1, 0.0) - s.uav_altitude(0, 0.0);
            let expected = ALTITUDE_STEP_M * (n.min(4) - 1) as f64;
            assert!((band - expected).abs() < 1e-9, "{n} UAVs: band {band} m");
        }
        let largest = &c.points[6].config.scenario;
        assert_eq!(largest.uavs.count as usize, MAX_UAVS);
        assert_eq!(largest.region.half_extent_m, 1000.0);
        assert_eq!(largest.targets.count, 128);
    }

    #[test]
    fn every_exchange_runs_every_size_in_the_order_given() {
        let c = parse(&["--uavs", "4,1", "--out", "o"]).unwrap();
        assert_eq!(c.exchanges, vec![Exchange::Sets, Exchange::Measurements]);
        let runs: Vec<(Exchange, u32)> = c
            .points
            .iter()
            .map(|p| (p.series.exchange, p.uavs))
            .collect();
        assert_eq!(
            runs,
            vec![
                (Exchange::Sets, 1),
                (Exchange::Sets, 4),
                (Exchange::Measurements, 1),
                (Exchange::Measurements, 4),
            ]
        );
        for p in &c.points {
            assert_eq!(p.config.scenario.comms.exchange, p.series.exchange);
            assert_eq!(p.series.window, WindowChoice::Whole);
            assert_eq!(p.window_m(), None);
            let dir = format!("o/runs/{}/uavs-{}", p.series.exchange.name(), p.uavs);
            assert_eq!(p.config.out, PathBuf::from(dir));
        }
        let ids: std::collections::BTreeSet<_> = c
            .points
            .iter()
            .map(|p| p.config.run_id.to_string())
            .collect();
        assert_eq!(ids.len(), 4, "every run has its own id");

        // The order given, each once; the flag wins over `--set`.
        let c = parse(&[
            "--uavs",
            "2",
            "--exchange",
            "measurements,sets,measurements",
            "--set",
            "comms.exchange=sets",
        ])
        .unwrap();
        assert_eq!(c.exchanges, vec![Exchange::Measurements, Exchange::Sets]);
        assert_eq!(c.points.len(), 2);
        assert_eq!(
            c.points[0].config.scenario.comms.exchange,
            Exchange::Measurements
        );
    }

    #[test]
    fn every_exchange_runs_under_every_window_and_auto_is_each_fleets_guidance_reach() {
        let c = parse(&[
            "--uavs",
            "16,4",
            "--exchange",
            "measurements",
            "--window-m",
            "auto,inf,150,auto",
            "--set",
            "estimator.window_m=10",
            "--out",
            "o",
        ])
        .unwrap();
        let auto = Series {
            exchange: Exchange::Measurements,
            window: WindowChoice::Auto,
        };
        let whole = Series {
            window: WindowChoice::Whole,
            ..auto
        };
        let metres = Series {
            window: WindowChoice::Metres(150.0),
            ..auto
        };
        assert_eq!(c.series, vec![auto, whole, metres]);
        let runs: Vec<(Series, u32, Option<f64>, String)> = c
            .points
            .iter()
            .map(|p| {
                let dir = p.config.out.display().to_string();
                (p.series, p.uavs, p.window_m(), dir)
            })
            .collect();
        // The 4-UAV and the 16-UAV fleets fly the same altitude band: the same reach.
        let reach = Scenario::default().guidance_reach_m();
        assert_eq!(reach, 320.0);
        assert_eq!(
            runs,
            vec![
                (
                    auto,
                    4,
                    Some(reach),
                    "o/runs/measurements_wauto/uavs-4".into()
                ),
                (
                    auto,
                    16,
                    Some(reach),
                    "o/runs/measurements_wauto/uavs-16".into()
                ),
                (whole, 4, None, "o/runs/measurements/uavs-4".into()),
                (whole, 16, None, "o/runs/measurements/uavs-16".into()),
                (
                    metres,
                    4,
                    Some(150.0),
                    "o/runs/measurements_w150/uavs-4".into()
                ),
                (
                    metres,
                    16,
                    Some(150.0),
                    "o/runs/measurements_w150/uavs-16".into()
                ),
            ]
        );
        // The flag wins over `--set`, and every run is its own.
        assert!(c.points[2].config.scenario.estimator.window_m.is_infinite());
        let ids: std::collections::BTreeSet<_> = c
            .points
            .iter()
            .map(|p| p.config.run_id.to_string())
            .collect();
        assert_eq!(ids.len(), 6);
        // A fleet lower than 4 UAVs' band sees less ground: a shorter reach.
        let c = parse(&["--uavs", "1", "--window-m", "auto"]).unwrap();
        assert_eq!(
            c.points[0].window_m(),
            Some(c.points[0].config.scenario.guidance_reach_m())
        );
        assert!(c.points[0].window_m().unwrap() < reach);
    }

    #[test]
    fn bad_flags_are_named() {
        for (args, says) in [
            (&["--uavs", "0"][..], "--uavs 0: every fleet size must be 1"),
            (&["--uavs", "2,65"], "--uavs 65"),
            (
                &["--uavs", "1,2,4,8,16,32,64,128"],
                "--uavs 128: every fleet size must be 1 to 64, the largest fleet the protocol \
                 carries",
            ),
            (&["--duration", "0"], "--duration 0: must be a positive"),
            (&["--duration=-3"], "--duration -3"),
            (&["--duration", "NaN"], "--duration NaN"),
            (&["--uavs", ""], "--uavs"),
            (&["--exchange", "bogus"], "--exchange"),
            (&["--exchange", "sets,bogus"], "--exchange"),
            (&["--exchange", ""], "--exchange"),
            (
                &["--window-m", "0"],
                "a window is `inf`, `auto` or a positive number",
            ),
            (&["--window-m", "inf,wide"], "--window-m"),
            (&["--window-m", ""], "--window-m"),
            (&["--set", "region.half_extent_m=1"], "half_extent_m"),
        ] {
            let e = parse(args).unwrap_err();
            assert!(e.contains(says), "{args:?}: {e}");
        }
    }
}
