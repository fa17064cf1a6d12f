//! `fleet render`: one UAV's frame at a given time, as pictures and JSON.

use std::path::{Path, PathBuf};

use clap::Args;
use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use serde::Serialize;
use world_server::World;

use fleet_observe::pictures::frame::{draw_depth, draw_labels};
use fleet_observe::pictures::topview::draw_topview;
use fleet_process::usage::{ScenarioArgs, UsageError};

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

/// What `frame.json` holds: the header and the boxes (the pixels are in the pictures).
#[derive(Debug, Serialize)]
struct FrameJson {
    header: HeaderJson,
    boxes: Vec<BoxJson>,
    label_counts: LabelCounts,
}

#[derive(Debug, Serialize)]
struct HeaderJson {
    step: u64,
    time_s: f64,
    uav: u32,
    rows: u32,
    cols: u32,
    box_count: u32,
    camera_position: [f64; 3],
    camera_yaw: f64,
    camera_tilt: f64,
    camera_aperture: f64,
    depth_noise: [f64; 2],
    checksum: String,
}

#[derive(Debug, Serialize)]
struct BoxJson {
    id: u32,
    r0: u32,
    c0: u32,
    r1: u32,
    c1: u32,
}

#[derive(Debug, Default, Serialize)]
struct LabelCounts {
    ground: usize,
    target: usize,
    obstacle: usize,
    unknown: usize,
}

/// Builds the world, advances it to the frame's step, renders the UAV's frame and writes
/// `labels.png`, `depth.png`, `topview.png` and `frame.json` into the output directory.
pub fn command(config: &RenderConfig) -> anyhow::Result<()> {
    let mut world = World::new(&config.scenario)?;
    while world.step() < config.step {
        world.advance();
    }
    let uav = config.uav as usize;
    let mut frame = CvsFrame::new_boxed();
    world.render(uav, 0, &mut frame);
    std::fs::create_dir_all(&config.out)?;
    let out = &config.out;
    draw_labels(&frame, &out.join("labels.png"))?;
    draw_depth(&frame, &out.join("depth.png"))?;
    draw_topview(&world, uav, &out.join("topview.png"))?;
    write_json(&frame, &out.join("frame.json"))?;
    println!(
        "UAV {uav} at t = {:.1} s (step {}): {} boxes; pictures in {}",
        frame.header.time_s,
        frame.header.step,
        frame.boxes().len(),
        out.display()
    );
    Ok(())
}

fn write_json(frame: &CvsFrame, path: &Path) -> anyhow::Result<()> {
    let h = &frame.header;
    let mut counts = LabelCounts::default();
    for &b in &frame.labels[..frame.pixel_count()] {
        match protocol::frame::Label::from_u8(b) {
            protocol::frame::Label::Ground => counts.ground += 1,
            protocol::frame::Label::Target => counts.target += 1,
            protocol::frame::Label::Obstacle => counts.obstacle += 1,
            protocol::frame::Label::Unknown => counts.unknown += 1,
        }
    }
    let json = FrameJson {
        header: HeaderJson {
            step: h.step,
            time_s: h.time_s,
            uav: h.uav,
            rows: h.rows,
            cols: h.cols,
            box_count: h.box_count,
            camera_position: h.camera_position,
            camera_yaw: h.camera_yaw,
            camera_tilt: h.camera_tilt,
            camera_aperture: h.camera_aperture,
            depth_noise: h.depth_noise,
            checksum: format!("{:016x}", h.checksum),
        },
        boxes: frame
            .boxes()
            .iter()
            .map(|b| BoxJson {
                id: b.id,
                r0: b.r0,
                c0: b.c0,
                r1: b.r1,
                c1: b.c1,
            })
            .collect(),
        label_counts: counts,
    };
    std::fs::write(path, serde_json::to_string_pretty(&json)? + "\n")?;
    Ok(())
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
}
