//! Bit-raster set operations on the default 1000 x 1000 grid (0.5 m cells):
//! `cargo bench -p protocol --bench raster`.

use divan::{Bencher, black_box};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sets::grid::GroundGrid;
use sets::math::{Point2, Real};
use sets::raster::{CellSet, Coverage};

fn main() {
    divan::main();
}

fn grid() -> GroundGrid {
    GroundGrid::new(250.0, 0.5)
}

/// Discs of 3 to 20 m placed at random until about `fraction` of the grid is covered: the
/// shape of an undetected set after a while of searching.
fn blobs(grid: &GroundGrid, seed: u64, fraction: Real) -> CellSet {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut set = CellSet::empty(grid);
    let target = (grid.cell_count() as Real * fraction) as u64;
    while set.count() < target {
        for _ in 0..20 {
            let c = Point2::new(
                rng.random_range(-250.0..250.0),
                rng.random_range(-250.0..250.0),
            );
            set.fill_disc(grid, c, rng.random_range(3.0..20.0), Coverage::Outer);
        }
    }
    set
}

/// A regular octagon 100 m across, turned so no edge is axis-aligned.
fn octagon() -> Vec<Point2> {
    (0..8)
        .map(|k| {
            let a = 0.3 + k as Real * std::f64::consts::TAU / 8.0;
            Point2::new(12.0 + 50.0 * a.cos(), -7.0 + 50.0 * a.sin())
        })
        .collect()
}

#[divan::bench(args = [1.0, 6.0])]
fn dilate(bencher: Bencher, radius_m: Real) {
    let g = grid();
    let set = blobs(&g, 1, 0.2);
    bencher.bench(|| black_box(&set).dilate(&g, radius_m));
}

#[divan::bench(args = [Coverage::Outer, Coverage::Inner])]
fn fill_polygon_100m(bencher: Bencher, coverage: Coverage) {
    let g = grid();
    let poly = octagon();
    bencher.bench(|| {
        let mut s = CellSet::empty(&g);
        s.fill_convex_polygon(&g, black_box(&poly), coverage);
        s
    });
}

#[divan::bench(args = [Coverage::Outer, Coverage::Inner])]
fn fill_disc_3m(bencher: Bencher, coverage: Coverage) {
    let g = grid();
    let mut s = CellSet::empty(&g);
    bencher.bench_local(|| {
        s.fill_disc(&g, black_box(Point2::new(1.3, 2.7)), 3.0, coverage);
    });
}

mod codec {
    use super::*;

    /// The undetected set: 20 % of the grid in blobs.
    #[divan::bench]
    fn encode_blobs(bencher: Bencher) {
        let set = blobs(&grid(), 2, 0.2);
        bencher.bench(|| black_box(&set).encode());
    }

    /// The runs of the undetected set counted without writing them.
    #[divan::bench]
    fn count_runs_blobs(bencher: Bencher) {
        let set = blobs(&grid(), 2, 0.2);
        bencher.bench(|| black_box(&set).encoded_run_count());
    }

    #[divan::bench]
    fn decode_blobs(bencher: Bencher) {
        let g = grid();
        let e = blobs(&g, 2, 0.2).encode();
        bencher.bench(|| CellSet::decode(&g, black_box(&e)));
    }

    /// A target set: one disc of 10 m.
    #[divan::bench]
    fn encode_target(bencher: Bencher) {
        let g = grid();
        let mut set = CellSet::empty(&g);
        set.fill_disc(&g, Point2::new(30.0, -40.0), 10.0, Coverage::Outer);
        bencher.bench(|| black_box(&set).encode());
    }

    #[divan::bench]
    fn count_runs_target(bencher: Bencher) {
        let g = grid();
        let mut set = CellSet::empty(&g);
        set.fill_disc(&g, Point2::new(30.0, -40.0), 10.0, Coverage::Outer);
        bencher.bench(|| black_box(&set).encoded_run_count());
    }

    #[divan::bench]
    fn decode_target(bencher: Bencher) {
        let g = grid();
        let mut set = CellSet::empty(&g);
        set.fill_disc(&g, Point2::new(30.0, -40.0), 10.0, Coverage::Outer);
        let e = set.encode();
        bencher.bench(|| CellSet::decode(&g, black_box(&e)));
    }
}

mod algebra {
    use super::*;

    fn pair() -> (CellSet, CellSet) {
        let g = grid();
        (blobs(&g, 3, 0.2), blobs(&g, 4, 0.5))
    }

    #[divan::bench]
    fn and_assign(bencher: Bencher) {
        let (mut a, b) = pair();
        bencher.bench_local(|| a.and_assign(black_box(&b)));
    }

    #[divan::bench]
    fn or_assign(bencher: Bencher) {
        let (mut a, b) = pair();
        bencher.bench_local(|| a.or_assign(black_box(&b)));
    }

    #[divan::bench]
    fn and_not_assign(bencher: Bencher) {
        let (mut a, b) = pair();
        bencher.bench_local(|| a.and_not_assign(black_box(&b)));
    }

    #[divan::bench]
    fn count(bencher: Bencher) {
        let (a, _) = pair();
        bencher.bench(|| black_box(&a).count());
    }

    #[divan::bench]
    fn intersection_count(bencher: Bencher) {
        let (a, b) = pair();
        bencher.bench(|| black_box(&a).intersection_count(black_box(&b)));
    }

    #[divan::bench]
    fn bounding_box(bencher: Bencher) {
        let (a, _) = pair();
        bencher.bench(|| black_box(&a).bounding_box());
    }

    #[divan::bench]
    fn barycentre(bencher: Bencher) {
        let g = grid();
        let (a, _) = pair();
        bencher.bench(|| black_box(&a).barycentre(&g));
    }
}

/// The exact gap field of a frame's window (300 x 300 cells, 150 m): what correcting a set
/// with a frame's proven-free ground costs.
#[divan::bench]
fn gap_field_frame_window(bencher: Bencher) {
    use sets::raster::CellBox;
    use sets::raster::distance::GapField;
    let g = grid();
    // Seeds where the ground was not proven free: the complement of blobs covering about
    // 80 % of the window, as around a frame's footprint.
    let free = blobs(&g, 3, 0.8);
    let window = CellBox {
        x0: 300,
        y0: 300,
        x1: 599,
        y1: 599,
    };
    let seeds: Vec<bool> = free
        .window_flags(&window, false)
        .iter()
        .map(|f| !f)
        .collect();
    let mut field = GapField::default();
    bencher.bench_local(|| black_box(field.compute(black_box(&window), black_box(&seeds)).len()));
}

/// Clearing a frame's free ground from `X̄` (`ReachSet::clear`): a camera's trapezoid
/// footprint, 120 m deep and 60 to 200 m wide (240 x 400 cells, about half of them free, as
/// in a 16-UAV run's frames), less the blobs of ground it did not prove free, applied to a set
/// that covers the grid. What applying one peer's measurement costs `X̄` under the
/// measurement exchange: the transform over the window and the raise of every free cell.
#[divan::bench]
fn reach_clear_frame_window(bencher: Bencher) {
    use sets::raster::ReachSet;
    let g = grid();
    let footprint = [
        Point2::new(-30.0, -60.0),
        Point2::new(30.0, -60.0),
        Point2::new(100.0, 60.0),
        Point2::new(-100.0, 60.0),
    ];
    let mut free = CellSet::empty(&g);
    free.fill_convex_polygon(&g, &footprint, Coverage::Inner);
    free.and_not_assign(&blobs(&g, 5, 0.1));
    let window = free.bounding_box().expect("a footprint");
    let mut set = ReachSet::full(&g);
    set.advance(10.0);
    let mut clock = 10.0;
    bencher.bench_local(|| {
        clock += 1.0;
        set.advance(clock);
        set.clear(&g, black_box(&free), &window);
    });
}
