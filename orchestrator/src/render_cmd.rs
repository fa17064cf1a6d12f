//! `fleet render`: one UAV's frame at a given time, as pictures and JSON.

use std::path::Path;

use protocol::frame::CvsFrame;
use serde::Serialize;
use world_server::World;

use crate::cli::RenderConfig;
use crate::pictures::frame::{draw_depth, draw_labels};
use crate::pictures::topview::draw_topview;

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
pub fn run(config: &RenderConfig) -> anyhow::Result<()> {
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
