//! The guarantee of [`ReachSet::clear_around`], checked against exact continuous geometry with
//! walls: ground no target enters, which targets must drive around.
//!
//! The reference holds the possible target positions, sampled (3 x 3 points per cell, strictly
//! inside it, two of them per axis a hair from its sides, where the gaps are tightest), and moves them with the exact shortest paths around the walls: a sample is
//! possible after a move of `r` when a possible sample is within `r` of it along a path that
//! does not cross a wall's interior (a visibility graph over the samples and the walls'
//! corners, where shortest paths bend). Walls are rectangles of cells apart from one another,
//! so the union of their interiors is the union of the open rectangles. Every sample the
//! reference holds is a position some target can really be at, so a sample outside the set's
//! cells is a broken guarantee.

mod common;

use common::{box_set, cell_box};
use proptest::prelude::*;
use sets::grid::{CellIndex, GroundGrid};
use sets::math::Point2;
use sets::raster::{CellBox, CellSet, ReachSet};

/// Where the samples sit across a cell, as fractions of its side.
const SAMPLES: [f64; 3] = [0.02, 0.5, 0.98];

fn grid() -> GroundGrid {
    GroundGrid::new(4.0, 0.5) // 16 x 16 cells
}

/// An open axis-aligned rectangle, metres.
#[derive(Clone, Copy, Debug)]
struct Wall {
    min: Point2,
    max: Point2,
}

impl Wall {
    fn of(g: &GroundGrid, b: &CellBox) -> Wall {
        Wall {
            min: g.cell_rect((b.x0, b.y0)).min,
            max: g.cell_rect((b.x1, b.y1)).max,
        }
    }

    /// Whether the segment `a b` passes through the open rectangle.
    fn cuts(&self, a: Point2, b: Point2) -> bool {
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for (p, d, min, max) in [
            (a.x, b.x - a.x, self.min.x, self.max.x),
            (a.y, b.y - a.y, self.min.y, self.max.y),
        ] {
            if d == 0.0 {
                if p <= min || p >= max {
                    return false;
                }
            } else {
                let (t0, t1) = ((min - p) / d, (max - p) / d);
                lo = lo.max(t0.min(t1));
                hi = hi.min(t0.max(t1));
            }
        }
        lo < hi
    }
}

/// Shortest paths around the walls between samples, through the walls' corners.
struct Paths {
    samples: Vec<(Point2, CellIndex)>,
    corners: Vec<Point2>,
    /// Whether sample `i` sees sample `j` (row-major `i * n + j`).
    sees: Vec<bool>,
    /// Whether sample `i` sees corner `k`.
    sees_corner: Vec<bool>,
    /// Shortest distance between corners `k` and `l`.
    between_corners: Vec<f64>,
}

impl Paths {
    fn new(g: &GroundGrid, walls: &[Wall]) -> Paths {
        let mut samples = Vec::new();
        for iy in 0..g.ny {
            for ix in 0..g.nx {
                let r = g.cell_rect((ix, iy));
                for fy in SAMPLES {
                    for fx in SAMPLES {
                        let p = Point2::new(
                            r.min.x + fx * (r.max.x - r.min.x),
                            r.min.y + fy * (r.max.y - r.min.y),
                        );
                        samples.push((p, (ix, iy)));
                    }
                }
            }
        }
        let corners: Vec<Point2> = walls
            .iter()
            .flat_map(|w| {
                [
                    w.min,
                    Point2::new(w.max.x, w.min.y),
                    Point2::new(w.min.x, w.max.y),
                    w.max,
                ]
            })
            .collect();
        let clear = |a: Point2, b: Point2| !walls.iter().any(|w| w.cuts(a, b));
        let n = samples.len();
        let mut sees = vec![false; n * n];
        for i in 0..n {
            for j in i..n {
                let v = clear(samples[i].0, samples[j].0);
                sees[i * n + j] = v;
                sees[j * n + i] = v;
            }
        }
        let sees_corner = samples
            .iter()
            .flat_map(|(p, _)| corners.iter().map(|c| clear(*p, *c)).collect::<Vec<_>>())
            .collect();
        let m = corners.len();
        let mut between_corners = vec![f64::INFINITY; m * m];
        for k in 0..m {
            for l in 0..m {
                if clear(corners[k], corners[l]) {
                    between_corners[k * m + l] = (corners[k] - corners[l]).norm();
                }
            }
        }
        for via in 0..m {
            for k in 0..m {
                for l in 0..m {
                    let d = between_corners[k * m + via] + between_corners[via * m + l];
                    if d < between_corners[k * m + l] {
                        between_corners[k * m + l] = d;
                    }
                }
            }
        }
        Paths {
            samples,
            corners,
            sees,
            sees_corner,
            between_corners,
        }
    }

    /// The samples within `r` of a `possible` sample along paths around the walls.
    fn moved(&self, possible: &[bool], r: f64) -> Vec<bool> {
        let (n, m) = (self.samples.len(), self.corners.len());
        let held: Vec<usize> = (0..n).filter(|&i| possible[i]).collect();
        let mut to_corner = vec![f64::INFINITY; m];
        for &i in &held {
            for (k, best) in to_corner.iter_mut().enumerate() {
                if self.sees_corner[i * m + k] {
                    *best = best.min((self.samples[i].0 - self.corners[k]).norm());
                }
            }
        }
        let via: Vec<f64> = (0..m)
            .map(|l| {
                (0..m)
                    .map(|k| to_corner[k] + self.between_corners[k * m + l])
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        // A hair under `r`: what the reference keeps must be reachable for sure.
        let r = r - 1e-9;
        (0..n)
            .map(|j| {
                let q = self.samples[j].0;
                held.iter()
                    .any(|&i| self.sees[i * n + j] && (self.samples[i].0 - q).norm() <= r)
                    || (0..m).any(|k| {
                        self.sees_corner[j * m + k] && via[k] + (self.corners[k] - q).norm() <= r
                    })
            })
            .collect()
    }
}

#[derive(Clone, Debug)]
enum Event {
    Move(f64),
    Free(CellBox),
}

fn event(n: u32) -> impl Strategy<Value = Event> {
    prop_oneof![
        1 => (0.1f64..1.6).prop_map(Event::Move),
        1 => cell_box(n, 12).prop_map(Event::Free),
    ]
}

/// Whether two boxes of cells are at least one cell apart.
fn apart(a: &CellBox, b: &CellBox) -> bool {
    a.x1 + 1 < b.x0 || b.x1 + 1 < a.x0 || a.y1 + 1 < b.y0 || b.y1 + 1 < a.y0
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// No position a target can really be at, driving around the walls, is ever outside the
    /// set, through any history of motion and proven-free ground; and the set never holds
    /// more than the straight-line reach of [`ReachSet::clear`] gives.
    #[test]
    fn the_set_holds_every_position_reachable_around_the_walls(
        wall_boxes in proptest::collection::vec(cell_box(16, 6), 1..4),
        events in proptest::collection::vec(event(16), 1..20),
    ) {
        for (i, a) in wall_boxes.iter().enumerate() {
            for b in &wall_boxes[i + 1..] {
                prop_assume!(apart(a, b));
            }
        }
        let g = grid();
        let walls: Vec<Wall> = wall_boxes.iter().map(|b| Wall::of(&g, b)).collect();
        let mut blocked = CellSet::empty(&g);
        for b in &wall_boxes {
            blocked.or_assign(&box_set(&g, b));
        }
        let paths = Paths::new(&g, &walls);
        let mut possible: Vec<bool> =
            paths.samples.iter().map(|(_, c)| !blocked.contains(*c)).collect();
        let mut set = ReachSet::full(&g);
        let mut straight = ReachSet::full(&g);
        let mut clock = 0.0;
        for e in &events {
            match e {
                Event::Move(r) => {
                    possible = paths.moved(&possible, *r);
                    clock += r;
                    for s in [&mut set, &mut straight] {
                        let previous = s.cells().dilate(&g, *r);
                        s.advance(clock);
                        s.intersect(&previous);
                    }
                }
                Event::Free(b) => {
                    // As the estimator does: the walls are free at every frame.
                    let mut free = box_set(&g, b);
                    free.or_assign(&blocked);
                    for ((_, c), k) in paths.samples.iter().zip(possible.iter_mut()) {
                        *k &= !free.contains(*c);
                    }
                    set.clear_around(&g, &free, &blocked, b);
                    straight.clear(&g, &free, b);
                }
            }
            for ((p, c), k) in paths.samples.iter().zip(&possible) {
                prop_assert!(
                    !*k || set.contains(*c),
                    "possible position {:?} outside the set (cell {:?}) after {:?}", p, c, e
                );
            }
            prop_assert!(set.cells().is_subset_of(straight.cells()));
        }
    }
}

#[test]
fn ground_behind_a_wall_stays_clear_longer_than_in_the_open() {
    // 40 x 40 cells of 0.5 m. Everything is proven free but a strip along the bottom rows;
    // a wall (rows 6..=7, x 4..=35) stands between the strip and the ground above it.
    let g = GroundGrid::new(10.0, 0.5);
    let all = CellBox {
        x0: 0,
        y0: 0,
        x1: 39,
        y1: 39,
    };
    let wall = CellBox {
        x0: 4,
        y0: 6,
        x1: 35,
        y1: 7,
    };
    let blocked = box_set(&g, &wall);
    let mut free = CellSet::full(&g);
    for iy in 0..=1 {
        for ix in 0..40 {
            free.set((ix, iy), false);
        }
    }
    let mut around = ReachSet::full(&g);
    around.clear_around(&g, &free, &blocked, &all);
    let mut straight = ReachSet::full(&g);
    straight.clear(&g, &free, &all);
    // 5 m later: straight through the wall, the cell (20, 12) is 5 m from the strip; around
    // the wall's ends it is more than 12 m away.
    around.advance(5.0);
    straight.advance(5.0);
    assert!(straight.contains((20, 12)));
    assert!(!around.contains((20, 12)));
    assert!(around.clearance_m((20, 12)).unwrap() > 1.0);
    // Near the wall's ends both reach round: the bound is never above the straight one there.
    assert!(around.cells().is_subset_of(straight.cells()));
    assert!(around.contains((2, 8)));
}
