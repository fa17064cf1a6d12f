//! The estimator's results pinned bit for bit: a seeded scenario rendered by the real world,
//! every agent's step and every fusion folded into a running digest of the sets (`X̄` and
//! every `X_j` with their reach and clock, `S^o`, the OEM), compared with the digests recorded
//! when the test was written. A change that makes any set differ by one cell or one reach unit
//! at any step fails here; speed work must keep these constants.
//!
//! Recorded again when `estimator.depth_ray = "any"` became the default (the frustum rule for
//! `S^o` and the map); with `"centre"` the run gave the digests recorded before, bit for bit.
//!
//! `SETFLEET_PRINT_DIGESTS=1 cargo test -p sim --test pinned -- --nocapture` prints the
//! digests a run computes (to record them after a deliberate change of the results).

use estimator::EstimatorState;
use estimator::occupancy::OccupancyMap;
use protocol::scenario::{Exchange, Scenario, SetGrowth};
use sets::raster::{CellSet, ReachSet};
use sim::{Fleet, FleetOptions};

const RUN_TAG: u64 = 0x0b17_1de7;

/// FNV-1a, folded word by word: stable across runs, machines and builds.
#[derive(Clone, Copy, Debug)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    fn word(&mut self, w: u64) {
        self.0 = (self.0 ^ w).wrapping_mul(0x100_0000_01b3);
    }
}

fn fold_cells(h: &mut Fnv, set: &CellSet) {
    h.word(set.digest());
    h.word(set.count());
}

fn fold_reach(h: &mut Fnv, set: &ReachSet) {
    fold_cells(h, set.cells());
    h.word(set.clock_m().to_bits());
    let (_, base, relative) = set.to_parts();
    h.word(u64::from(base));
    for &r in &relative {
        h.word(u64::from(r));
    }
}

fn fold_map(h: &mut Fnv, map: &OccupancyMap) {
    for ((ix, iy), cell) in map.known_cells() {
        h.word(u64::from(ix) << 32 | u64::from(iy));
        h.word(u64::from(cell.status.code()) << 32 | u64::from(cell.height_m.to_bits()));
    }
}

/// The digest of one state's sets: `X̄`, every `X_j` (with its id), `S^o`, the OEM.
fn state_digest(state: &EstimatorState) -> u64 {
    let mut h = Fnv::new();
    fold_reach(&mut h, &state.undetected);
    for (id, set) in &state.targets {
        h.word(u64::from(*id));
        fold_reach(&mut h, set);
    }
    fold_cells(&mut h, &state.obstacle_neighbourhood);
    fold_map(&mut h, &state.oem);
    h.0
}

/// The pinned runs' scenario: 4 UAVs and 8 cars on 240 x 240 m, with `sets` and `exchange`.
/// The digests of the set exchange were recorded when it was the default, and are kept.
fn scenario(seed: u64, sets: SetGrowth, exchange: Exchange) -> Scenario {
    let mut s = Scenario {
        seed,
        ..Scenario::default()
    };
    s.region.half_extent_m = 120.0;
    s.camera.rows = 180;
    s.camera.cols = 240;
    s.targets.count = 8;
    s.uavs.count = 4;
    s.estimator.sets = sets;
    s.comms.exchange = exchange;
    s
}

/// What a run folded: the running digest after every `every` steps, and how many targets the
/// fleet identified (so that the pinned run is known to measure targets).
struct Digests {
    chain: Vec<u64>,
    identified: usize,
}

/// Runs every UAV's estimator over `steps` frames, the yaws swinging on a fixed schedule so
/// that the views turn as well as move, every agent fusing every other's encoded estimate at
/// every step. The running digest folds every agent's state after its step and after its
/// fusion.
fn run(scenario: &Scenario, steps: u64, every: u64) -> Digests {
    let options = FleetOptions {
        run_tag: RUN_TAG,
        ..FleetOptions::default()
    };
    let mut fleet = Fleet::new(scenario, options).expect("world");
    let n = fleet.uav_count();
    let yaw0: Vec<f64> = (0..n)
        .map(|i| fleet.world().uav_state(i).expect("uav").yaw)
        .collect();
    let mut chain = Fnv::new();
    let mut out = Vec::new();
    for k in 0..steps {
        for (i, &y) in yaw0.iter().enumerate() {
            // Whole radians per 12 steps: exact in binary, the same everywhere.
            let swing = if (k / 12 + i as u64).is_multiple_of(3) {
                -1.0
            } else {
                ((k / 12 + i as u64) % 3) as f64 * 0.5
            };
            fleet.world_mut().set_yaw_ref(i, y + swing);
        }
        let mut sample = fleet.sample();
        fleet
            .sense(&mut sample, |s| {
                chain.word(state_digest(s.estimator.state()))
            })
            .expect("frame accepted");
        fleet
            .share(&mut sample, |_| {})
            .expect("estimates exchanged");
        for est in fleet.estimators() {
            chain.word(state_digest(est.state()));
        }
        if (k + 1).is_multiple_of(every) {
            out.push(chain.0);
        }
        fleet.advance();
    }
    let identified = fleet
        .estimators()
        .iter()
        .map(|e| e.state().targets.len())
        .max()
        .unwrap_or(0);
    Digests {
        chain: out,
        identified,
    }
}

fn check(name: &str, got: &Digests, pinned: &[u64]) {
    if std::env::var_os("SETFLEET_PRINT_DIGESTS").is_some() {
        let hex: Vec<String> = got.chain.iter().map(|d| format!("0x{d:016x}")).collect();
        eprintln!(
            "{name}: identified {}, [{}]",
            got.identified,
            hex.join(", ")
        );
    }
    assert!(got.identified > 0, "{name}: the run identified no target");
    for (k, (g, p)) in got.chain.iter().zip(pinned).enumerate() {
        assert_eq!(
            g, p,
            "{name}: the sets differ from the pinned ones by checkpoint {k} (0x{g:016x}, pinned 0x{p:016x})"
        );
    }
    assert_eq!(got.chain.len(), pinned.len(), "{name}: checkpoints");
}

#[test]
fn reach_sets_are_the_pinned_ones() {
    let got = run(&scenario(3, SetGrowth::Reach, Exchange::Sets), 80, 10);
    check(
        "reach",
        &got,
        &[
            0x9e33185e7c8f41df,
            0x8ad31c9aa4b8ef71,
            0x31a3605751c27692,
            0xf0b4e1407bb4313e,
            0x55bc64830da4bd2c,
            0x975d53f6e85d425b,
            0x8529c57fb144ed00,
            0x64d3e84620bc2f9c,
        ],
    );
}

#[test]
fn geodesic_sets_are_the_pinned_ones() {
    let got = run(&scenario(4, SetGrowth::Geodesic, Exchange::Sets), 40, 10);
    check(
        "geodesic",
        &got,
        &[
            0x232f4642fd03398f,
            0xdc1941d274b95a15,
            0x24274325c5ade1fb,
            0xd5b1d1fbb7468450,
        ],
    );
}

#[test]
fn whole_cell_sets_are_the_pinned_ones() {
    let got = run(&scenario(5, SetGrowth::Cells, Exchange::Sets), 40, 10);
    check(
        "cells",
        &got,
        &[
            0x0c244dd4abd647e3,
            0x3ce130824500bcbb,
            0xec0340aaeebb92d9,
            0x63135837f9666401,
        ],
    );
}

/// The default exchange: every agent applies its peers' measurements of the step.
#[test]
fn reach_sets_under_the_measurement_exchange_are_the_pinned_ones() {
    let got = run(
        &scenario(3, SetGrowth::Reach, Exchange::Measurements),
        80,
        10,
    );
    check(
        "reach, measurements",
        &got,
        &[
            0x0ed40a34e81a29b3,
            0xa0a73effe3663f4d,
            0x0f07dd671cff3d82,
            0xe38048de185eca2b,
            0x1d43c23234662cda,
            0xc6c5ec9900a661b9,
            0x3749843fe0e1f91c,
            0xfd5436ce65f2afe8,
        ],
    );
}
