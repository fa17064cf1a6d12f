//! Rendering speed of the default 360 x 480 camera over the default city, on 1 and 2 threads.
//!
//! `cargo bench -p world-server --bench render`: the `frame` bench reports time per frame
//! (frames/s is its inverse) and rays/s as its throughput.

use divan::Bencher;
use divan::counter::ItemsCount;
use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use world_server::World;
use world_server::render::rays_per_frame;

fn main() {
    divan::main();
}

/// A world a few seconds into the default scenario, so the UAVs look over the city.
fn world() -> World {
    let mut world = World::new(&Scenario::default()).unwrap_or_else(|e| panic!("{e}"));
    for _ in 0..20 {
        world.advance();
    }
    world
}

#[divan::bench(args = [1, 2], sample_count = 40)]
fn frame(bencher: Bencher, threads: usize) {
    let world = world();
    let s = world.scenario();
    let rays = rays_per_frame(s.camera.rows, s.camera.cols);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap_or_else(|e| panic!("{e}"));
    let mut frame = CvsFrame::new_boxed();
    let mut uav = 0;
    bencher.counter(ItemsCount::new(rays)).bench_local(|| {
        pool.install(|| world.render(uav, 1, &mut frame));
        uav = (uav + 1) % world.uav_count();
    });
}
