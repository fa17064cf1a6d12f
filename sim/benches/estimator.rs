//! Estimator benchmarks on the default scenario (360 x 480 camera, 0.5 m cells):
//! one step on a real frame, its phases, fusion, applying a peer's measurement (the
//! measurement exchange), and the estimate message size after ~100 steps.
//!
//! `cargo bench -p sim --bench estimator`; `SETFLEET_BENCH_SCENARIO=FILE` runs it on that
//! scenario file instead (e.g. the `scenario.toml` of a 16-UAV run).

use std::sync::OnceLock;
use std::time::Duration;

use divan::Bencher;
use divan::counter::BytesCount;
use estimator::{Estimator, Measurement, PeerEstimate, StepTimings};
use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use sim::{Fleet, FleetOptions};

/// Steps run before measuring, so the sets look like a run's rather than a fresh start's.
const WARMUP_STEPS: u64 = 100;

struct Fixture {
    /// The measured UAV's estimator after the warm-up, fused with its peers.
    estimator: Estimator,
    /// A peer's estimate at the same step.
    peer: PeerEstimate,
    /// Its next frame.
    frame: Box<CvsFrame>,
    /// The measured UAV's estimator after its next frame.
    stepped: Estimator,
    /// A peer's measurement of that frame's step.
    measurement: Measurement,
    /// The encoded estimate message of that UAV after the warm-up (a delta, not a full map).
    message: Vec<u8>,
}

fn fixture() -> &'static Fixture {
    static FIXTURE: OnceLock<Fixture> = OnceLock::new();
    FIXTURE.get_or_init(|| {
        let scenario = match std::env::var_os("SETFLEET_BENCH_SCENARIO") {
            Some(path) => Scenario::load(Some(std::path::Path::new(&path)), &[])
                .expect("SETFLEET_BENCH_SCENARIO names a valid scenario file"),
            None => Scenario::default(),
        };
        let mut fleet = Fleet::new(&scenario, FleetOptions::default()).expect("the world");
        let n = fleet.uav_count();
        let mut sizes = Vec::new();
        for k in 0..WARMUP_STEPS {
            // Turn now and then so the views sweep the city as the guidance would make them.
            if k % 12 == 0 {
                for i in 0..n {
                    let yaw = fleet.world().uav_state(i).map_or(0.0, |s| s.yaw);
                    fleet.world_mut().set_yaw_ref(i, yaw + 0.5);
                }
            }
            sizes.extend(fleet.step().expect("step").message_bytes);
        }
        sizes.sort_unstable();
        eprintln!(
            "estimate message bytes over the warm-up: median {}, p99 {}, max {}",
            sizes[sizes.len() / 2],
            sizes[sizes.len() * 99 / 100],
            sizes[sizes.len() - 1]
        );
        // Measure the UAV that sees the most targets, so every phase has work.
        let world = fleet.world();
        let mut frame = CvsFrame::new_boxed();
        let chosen = (0..n)
            .max_by_key(|&i| {
                world.render(i, 1, &mut frame);
                (frame.header.box_count, std::cmp::Reverse(i))
            })
            .unwrap_or(0);
        world.render(chosen, 1, &mut frame);
        eprintln!(
            "measured UAV {chosen}: {} target boxes",
            frame.header.box_count
        );
        let estimators = fleet.estimators();
        let estimator = estimators[chosen].clone();
        print_phase_medians(&estimator, &frame);
        let other = (chosen + 1) % n;
        let peer = estimators[other].state().to_peer(other as u32);
        let mut stepped = estimator.clone();
        stepped.step(&frame).expect("the measured UAV's next frame");
        let mut peer_frame = CvsFrame::new_boxed();
        world.render(other, 1, &mut peer_frame);
        let (_, measurement) = estimators[other]
            .clone()
            .step_sharing(&peer_frame, other as u32)
            .expect("the peer's next frame");
        eprintln!(
            "the peer's measurement: box {:?}, {} free cells",
            measurement.free_ground.bounding_box(),
            measurement.free_ground.count()
        );
        Fixture {
            estimator,
            peer,
            frame,
            stepped,
            measurement,
            message: fleet.messages()[chosen].clone(),
        }
    })
}

/// Reads one phase's time out of a step's timings.
type Phase = fn(&StepTimings) -> Duration;

/// Medians of the phases of a step over repeated runs on the same frame, from the
/// [`estimator::StepReport`] timings.
fn print_phase_medians(estimator: &Estimator, frame: &CvsFrame) {
    let runs: Vec<StepTimings> = (0..41)
        .filter_map(|_| estimator.clone().step(frame).ok().map(|r| r.timings))
        .collect();
    let median = |f: Phase| {
        let mut v: Vec<Duration> = runs.iter().map(f).collect();
        v.sort_unstable();
        v.get(v.len() / 2).copied().unwrap_or_default()
    };
    eprintln!("step phases, median of {} runs:", runs.len());
    let phases: [(&str, Phase); 7] = [
        ("prediction", |t| t.prediction),
        ("free ground + hidden", |t| t.free_ground),
        ("measurement sets", |t| t.measurement_sets),
        ("obstacle sets", |t| t.obstacle_sets),
        ("oem", |t| t.oem),
        ("correction", |t| t.correction),
        ("total", |t| t.total),
    ];
    for (name, f) in phases {
        eprintln!("  {name:<22} {:>9.3} ms", median(f).as_secs_f64() * 1e3);
    }
}

fn main() {
    fixture();
    divan::main();
}

/// One estimator step on a default-scenario frame.
#[divan::bench(sample_count = 60, sample_size = 1)]
fn step(bencher: Bencher) {
    let f = fixture();
    bencher
        .with_inputs(|| f.estimator.clone())
        .bench_local_values(|mut e| e.step(&f.frame).map(|r| r.timings.total));
}

/// Fusing one peer's estimate of the same step.
#[divan::bench(sample_count = 60, sample_size = 1)]
fn fuse(bencher: Bencher) {
    let f = fixture();
    bencher
        .with_inputs(|| f.estimator.clone())
        .bench_local_values(|mut e| e.fuse(&f.peer));
}

/// Applying a peer's measurement of the same step (the measurement exchange's counterpart of
/// [`fuse`]).
#[divan::bench(sample_count = 60, sample_size = 1)]
fn apply(bencher: Bencher) {
    let f = fixture();
    bencher
        .with_inputs(|| f.stepped.clone())
        .bench_local_values(|mut e| e.apply(&f.measurement).measured.len());
}

/// Decoding and validating a typical estimate message (its size is the byte counter).
#[divan::bench]
fn decode_message(bencher: Bencher) {
    let f = fixture();
    let config = f.estimator.config().clone();
    bencher
        .counter(BytesCount::new(f.message.len()))
        .bench(|| PeerEstimate::from_bytes(&f.message, &config).map(|p| p.step));
}
