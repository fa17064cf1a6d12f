//! `fleet bench render`: frames of the default city rendered per thread count.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use world_server::World;
use world_server::render::rays_per_frame;

use super::{BenchCase, BenchReport, Metrics, Stats};
use fleet_process::usage::{ScenarioArgs, UsageError};

/// Frames rendered before measuring (caches, page faults, the pool's threads).
const WARM_UP_FRAMES: u32 = 5;

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

/// Renders `config.frames` frames per thread count after a warm-up, cycling through the UAVs
/// and advancing the world between frames so the views vary, and reports the frame times.
pub fn run(config: &BenchRenderConfig) -> anyhow::Result<BenchReport> {
    let mut report = BenchReport::new("render");
    let scenario = &config.scenario;
    let rays = rays_per_frame(scenario.camera.rows, scenario.camera.cols);
    let mut frame = CvsFrame::new_boxed();
    let mut best: Option<(usize, f64, f64)> = None;
    for &threads in &config.threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()?;
        let mut world = World::new(scenario)?;
        let uavs = world.uav_count().max(1);
        let times_ms = pool.install(|| {
            let mut times = Vec::with_capacity(config.frames as usize);
            for i in 0..(WARM_UP_FRAMES + config.frames) {
                let uav = i as usize % uavs;
                if uav == 0 && i > 0 {
                    world.advance();
                }
                let start = Instant::now();
                world.render(uav, 0, &mut frame);
                let ms = start.elapsed().as_secs_f64() * 1e3;
                if i >= WARM_UP_FRAMES {
                    times.push(ms);
                }
            }
            times
        });
        let stats =
            Stats::from_samples(&times_ms).ok_or_else(|| anyhow::anyhow!("no frame was timed"))?;
        let frames_per_s = 1e3 / stats.median;
        let rays_per_s = rays as f64 * frames_per_s;
        let mut metrics = Metrics::default();
        metrics.push("median_ms", stats.median);
        metrics.push("p10_ms", stats.p10);
        metrics.push("p90_ms", stats.p90);
        metrics.push("frames_per_s", frames_per_s);
        metrics.push("rays_per_s", rays_per_s);
        let mut params = BTreeMap::new();
        params.insert("threads".to_owned(), threads.into());
        params.insert("frames".to_owned(), config.frames.into());
        params.insert("rays_per_frame".to_owned(), rays.into());
        report.cases.push(BenchCase {
            name: format!("threads={threads}"),
            params,
            metrics,
        });
        if best.is_none_or(|(_, f, _)| frames_per_s > f) {
            best = Some((threads, frames_per_s, rays_per_s));
        }
    }
    if let Some((threads, frames_per_s, rays_per_s)) = best {
        report.summary.insert("best_threads".into(), threads.into());
        report
            .summary
            .insert("frames_per_s".into(), frames_per_s.into());
        report
            .summary
            .insert("rays_per_s".into(), rays_per_s.into());
    }
    report.summary.insert(
        "camera".into(),
        format!("{}x{}", scenario.camera.rows, scenario.camera.cols).into(),
    );
    Ok(report)
}
