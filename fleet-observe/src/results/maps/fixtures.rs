//! What the pictures' tests share: where they write, a small scenario flown for a while, and
//! reading a painted picture back at a ground point.

use std::path::{Path, PathBuf};

use plotters::prelude::*;
use std::collections::BTreeMap;
use std::sync::Arc;

use protocol::scenario::Scenario;
use protocol::wire::TargetTruth;
use sets::math::Point2;
use sets::raster::{CellSet, Coverage};
use world_server::World;

use super::chart::{Area, SIZE};
use super::raster::PlotRaster;
use crate::observe::FinalState;
use crate::observe::metrics::FusedSets;

/// Where a test writes its pictures: `$SETFLEET_KEEP_MAPS` (kept) or a fresh temp dir
/// (removed when the guard drops).
pub(super) struct OutDir {
    pub(super) path: PathBuf,
    keep: bool,
}

impl OutDir {
    pub(super) fn new(name: &str) -> OutDir {
        let (path, keep) = match std::env::var_os("SETFLEET_KEEP_MAPS") {
            Some(dir) => (PathBuf::from(dir).join(name), true),
            None => (
                std::env::temp_dir().join(format!(
                    "setfleet-maps-{}-{name}-{}",
                    std::process::id(),
                    std::time::SystemTime::now()
                        .duration_since(std::time::UNIX_EPOCH)
                        .unwrap()
                        .as_nanos()
                )),
                false,
            ),
        };
        std::fs::create_dir_all(&path).unwrap();
        OutDir { path, keep }
    }
}

impl Drop for OutDir {
    fn drop(&mut self) {
        if self.keep {
            eprintln!("pictures kept in {}", self.path.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

pub(super) fn small_scenario() -> Scenario {
    Scenario::load(
        None,
        &[
            "region.half_extent_m=40".into(),
            "targets.count=3".into(),
            "uavs.count=2".into(),
        ],
    )
    .unwrap()
}

pub(super) fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap();
    assert!(
        bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
        "{} is not a PNG",
        path.display()
    );
    assert!(
        bytes.len() > 10_000,
        "{} is only {} bytes",
        path.display(),
        bytes.len()
    );
}

/// Paints with `paint` into memory; returns the picture's RGB bytes and the plot raster.
pub(super) fn paint_in_memory(
    paint: impl FnOnce(&Area<'_>) -> anyhow::Result<PlotRaster>,
) -> (Vec<u8>, PlotRaster) {
    let mut buf = vec![0u8; SIZE.0 as usize * SIZE.1 as usize * 3];
    let raster = {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        let raster = paint(&root).unwrap();
        root.present().unwrap();
        raster
    };
    (buf, raster)
}

/// The picture's colour at ground point `(x, y)`.
pub(super) fn colour_at(buf: &[u8], raster: &PlotRaster, x: f64, y: f64) -> [u8; 3] {
    let (px, py) = raster.pixel_of(x, y).unwrap();
    let (col, row) = (raster.left + px as i32, raster.top + py as i32);
    let i = (row as usize * SIZE.0 as usize + col as usize) * 3;
    [buf[i], buf[i + 1], buf[i + 2]]
}

/// The world of `scenario` after `steps` steps, with each UAV's track.
pub(super) fn flown(scenario: &Scenario, steps: u32) -> (World, Vec<Vec<[f64; 2]>>) {
    let mut world = World::new(scenario).unwrap();
    let mut tracks = vec![Vec::new(); world.uav_count()];
    for _ in 0..steps {
        for (track, uav) in tracks.iter_mut().zip(world.uavs()) {
            track.push([uav.state.position.x, uav.state.position.y]);
        }
        world.advance();
    }
    (world, tracks)
}

pub(super) fn truth_of(world: &World) -> Vec<TargetTruth> {
    world
        .targets()
        .iter()
        .map(|car| TargetTruth {
            id: car.id,
            reserved: 0,
            ground: [car.position.x, car.position.y],
            heading: car.heading,
            speed: car.speed_mps,
        })
        .collect()
}

/// A final state over `world`'s city with every kind of set: `S^o` around the buildings,
/// explored ground, `X̄` elsewhere, a patch of `H̄` and two target sets.
pub(super) fn synthetic_state(scenario: &Scenario, world: &World) -> FinalState {
    let grid = scenario.grid();
    let targets = truth_of(world);
    let mut obstacle_neighbourhood = CellSet::empty(&grid);
    for b in &world.scene().buildings {
        let r = scenario.targets.safety_distance_m;
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                let c = grid.cell_centre((ix, iy));
                if c.x > b.min.x - r && c.x < b.max.x + r && c.y > b.min.y - r && c.y < b.max.y + r
                {
                    obstacle_neighbourhood.set((ix, iy), true);
                }
            }
        }
    }
    let mut explored = CellSet::empty(&grid);
    explored.fill_disc(&grid, Point2::new(-15.0, -15.0), 18.0, Coverage::Inner);
    explored.and_not_assign(&obstacle_neighbourhood);
    let mut undetected = CellSet::full(&grid);
    undetected.and_not_assign(&explored);
    undetected.and_not_assign(&obstacle_neighbourhood);
    let mut unseen = CellSet::empty(&grid);
    unseen.fill_disc(&grid, Point2::new(20.0, 20.0), 10.0, Coverage::Outer);
    let mut sets = BTreeMap::new();
    for t in targets.iter().take(2) {
        let mut s = CellSet::empty(&grid);
        s.fill_disc(
            &grid,
            Point2::new(t.ground[0], t.ground[1]),
            4.0,
            Coverage::Outer,
        );
        sets.insert(t.id, Arc::new(s));
    }
    FinalState {
        step: 40,
        time_s: 20.0,
        uav: 0,
        sets: FusedSets {
            undetected: Arc::new(undetected),
            targets: sets,
            obstacle_neighbourhood: Arc::new(obstacle_neighbourhood),
            explored: Arc::new(explored),
            unseen,
        },
        targets,
    }
}
