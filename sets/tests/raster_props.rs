//! Property tests of the bit-raster sets against exact geometry and a `HashSet` model: outer
//! rasterisation covers the shape and no more than it, inner rasterisation stays inside,
//! dilation reaches every point within the radius and no further, the algebra agrees with
//! the model, and decoding never panics.

use std::collections::HashSet;

use proptest::prelude::*;
use sets::grid::{CellIndex, GroundGrid, Rect};
use sets::math::{Point2, Real, convex_hull};
use sets::raster::{CellBox, CellSet, Coverage, EncodedSet};

/// Slack of the checks that a present cell is no larger than needed: far above the
/// rasteriser's margin (about 1e-9 relative), far below a cell.
const TOL: Real = 1e-6;

/// Grids of 10 to 59 columns and 10 to 89 rows (a polygon's fill keeps the extents of up to
/// 64 rows on the stack, of more in a vector: both are met).
fn grids() -> impl Strategy<Value = GroundGrid> {
    (-100.0..100.0, -100.0..100.0, 0.1..3.0, 10u32..60, 10u32..90).prop_map(
        |(ox, oy, cell_m, nx, ny)| GroundGrid {
            origin: Point2::new(ox, oy),
            cell_m,
            nx,
            ny,
        },
    )
}

/// A point in grid units `(u, v)` (0..1 spans the grid), from 20% outside to 20% past it.
fn unit_points(n: std::ops::Range<usize>) -> impl Strategy<Value = Vec<(Real, Real)>> {
    prop::collection::vec((-0.2..1.2, -0.2..1.2), n)
}

fn to_world(grid: &GroundGrid, (u, v): (Real, Real)) -> Point2 {
    let b = grid.bounds();
    Point2::new(
        b.min.x + u * (b.max.x - b.min.x),
        b.min.y + v * (b.max.y - b.min.y),
    )
}

/// Every cell of the grid whose closed square contains `p`.
fn cells_containing(grid: &GroundGrid, p: &Point2) -> Vec<CellIndex> {
    let (Some((c0, c1)), Some((r0, r1))) = (
        grid.columns_touching(p.x, p.x),
        grid.rows_touching(p.y, p.y),
    ) else {
        return Vec::new();
    };
    (r0..=r1)
        .flat_map(|iy| (c0..=c1).map(move |ix| (ix, iy)))
        .collect()
}

fn all_cells(grid: &GroundGrid) -> impl Iterator<Item = CellIndex> + '_ {
    (0..grid.ny).flat_map(move |iy| (0..grid.nx).map(move |ix| (ix, iy)))
}

/// Signed distance of `p` to the left of edge `a -> b` (positive inside a CCW polygon).
fn left_distance(a: &Point2, b: &Point2, p: &Point2) -> Real {
    let e = b - a;
    (e.x * (p.y - a.y) - e.y * (p.x - a.x)) / e.norm()
}

/// The smallest signed distance of `p` to the edges of CCW convex `hull` (>= 0 inside).
fn depth_in(hull: &[Point2], p: &Point2) -> Real {
    (0..hull.len())
        .map(|i| left_distance(&hull[i], &hull[(i + 1) % hull.len()], p))
        .fold(Real::INFINITY, Real::min)
}

/// Whether a cell's square and a CCW convex polygon are within `tol` of each other along
/// every separating axis candidate (the axes of the square and the polygon's edge normals).
fn square_meets_hull(square: &Rect, hull: &[Point2], tol: Real) -> bool {
    let (px0, px1) = hull
        .iter()
        .fold((Real::INFINITY, Real::NEG_INFINITY), |(a, b), p| {
            (a.min(p.x), b.max(p.x))
        });
    let (py0, py1) = hull
        .iter()
        .fold((Real::INFINITY, Real::NEG_INFINITY), |(a, b), p| {
            (a.min(p.y), b.max(p.y))
        });
    if px0 > square.max.x + tol || px1 < square.min.x - tol {
        return false;
    }
    if py0 > square.max.y + tol || py1 < square.min.y - tol {
        return false;
    }
    let corners = square.corners();
    (0..hull.len()).all(|i| {
        let (a, b) = (&hull[i], &hull[(i + 1) % hull.len()]);
        // The polygon lies left of each edge; the square is separated if wholly right of it.
        corners.iter().any(|c| left_distance(a, b, c) >= -tol)
    })
}

/// Sample points of the hull: a lattice finer than the cells over its bounding box (kept if
/// inside), its vertices and points along its edges.
fn hull_samples(grid: &GroundGrid, hull: &[Point2], jitter: (Real, Real)) -> Vec<Point2> {
    let mut out: Vec<Point2> = hull.to_vec();
    for i in 0..hull.len() {
        let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
        for k in 0..16 {
            let t = (k as Real + jitter.0) / 16.0;
            out.push(a + (b - a) * t);
        }
    }
    let step = grid.cell_m / 3.0;
    let (x0, x1) = hull
        .iter()
        .fold((Real::INFINITY, Real::NEG_INFINITY), |(a, b), p| {
            (a.min(p.x), b.max(p.x))
        });
    let (y0, y1) = hull
        .iter()
        .fold((Real::INFINITY, Real::NEG_INFINITY), |(a, b), p| {
            (a.min(p.y), b.max(p.y))
        });
    let bounds = grid.bounds();
    let (x0, x1) = (x0.max(bounds.min.x - step), x1.min(bounds.max.x + step));
    let (y0, y1) = (y0.max(bounds.min.y - step), y1.min(bounds.max.y + step));
    let mut y = y0 + jitter.1 * step;
    while y <= y1 {
        let mut x = x0 + jitter.0 * step;
        while x <= x1 {
            let p = Point2::new(x, y);
            if depth_in(hull, &p) >= 0.0 {
                out.push(p);
            }
            x += step;
        }
        y += step;
    }
    out
}

/// The polygon as a caller might pass it: either orientation, sometimes with a repeated
/// vertex.
fn as_passed(hull: &[Point2], reverse: bool, repeat: bool) -> Vec<Point2> {
    let mut poly = hull.to_vec();
    if repeat {
        poly.insert(1, poly[0]);
    }
    if reverse {
        poly.reverse();
    }
    poly
}

fn square_gap(a: CellIndex, b: CellIndex, cell_m: Real) -> Real {
    let gap = |p: u32, q: u32| (i64::from(p) - i64::from(q)).abs().saturating_sub(1).max(0) as Real;
    cell_m * gap(a.0, b.0).hypot(gap(a.1, b.1))
}

fn random_set(grid: &GroundGrid, cells: &[(Real, Real)]) -> CellSet {
    CellSet::from_cells(
        grid,
        cells.iter().map(|&(u, v)| {
            (
                ((u * grid.nx as Real) as u32).min(grid.nx - 1),
                ((v * grid.ny as Real) as u32).min(grid.ny - 1),
            )
        }),
    )
}

proptest! {
    #[test]
    fn outer_polygon_covers_the_polygon_and_no_more(
        grid in grids(),
        pts in unit_points(3..9),
        jitter in (0.0..1.0, 0.0..1.0),
        reverse in any::<bool>(),
        repeat in any::<bool>(),
    ) {
        let hull = convex_hull(&pts.iter().map(|&p| to_world(&grid, p)).collect::<Vec<_>>());
        prop_assume!(hull.len() >= 3);
        let mut set = CellSet::empty(&grid);
        set.fill_convex_polygon(&grid, &as_passed(&hull, reverse, repeat), Coverage::Outer);
        for p in hull_samples(&grid, &hull, jitter) {
            for c in cells_containing(&grid, &p) {
                prop_assert!(set.contains(c), "cell {:?} holds {:?} of the polygon", c, p);
            }
        }
        for c in set.iter() {
            prop_assert!(square_meets_hull(&grid.cell_rect(c), &hull, TOL), "cell {:?}", c);
        }
    }

    #[test]
    fn inner_polygon_stays_inside_and_keeps_cells_well_inside(
        grid in grids(),
        pts in unit_points(3..9),
        reverse in any::<bool>(),
        repeat in any::<bool>(),
    ) {
        let hull = convex_hull(&pts.iter().map(|&p| to_world(&grid, p)).collect::<Vec<_>>());
        prop_assume!(hull.len() >= 3);
        let mut set = CellSet::empty(&grid);
        set.fill_convex_polygon(&grid, &as_passed(&hull, reverse, repeat), Coverage::Inner);
        for c in all_cells(&grid) {
            let corners = grid.cell_rect(c).corners();
            let depth = corners.iter().map(|p| depth_in(&hull, p)).fold(Real::INFINITY, Real::min);
            if set.contains(c) {
                prop_assert!(depth >= 0.0, "cell {:?} pokes out by {}", c, -depth);
            } else {
                prop_assert!(depth < TOL, "cell {:?} is {} inside but missing", c, depth);
            }
        }
    }

    #[test]
    fn degenerate_polygons_touch_outer_and_add_nothing_inner(
        grid in grids(),
        pts in unit_points(1..3),
        along in prop::collection::vec(0.0..=1.0, 16),
    ) {
        let poly: Vec<Point2> = pts.iter().map(|&p| to_world(&grid, p)).collect();
        let mut outer = CellSet::empty(&grid);
        outer.fill_convex_polygon(&grid, &poly, Coverage::Outer);
        let (a, b) = (poly[0], poly[poly.len() - 1]);
        for t in along.iter().copied().chain([0.0, 1.0]) {
            for c in cells_containing(&grid, &(a + (b - a) * t)) {
                prop_assert!(outer.contains(c));
            }
        }
        let mut inner = CellSet::empty(&grid);
        inner.fill_convex_polygon(&grid, &poly, Coverage::Inner);
        // Collinear: the segment repeated with its midpoint has no area either.
        inner.fill_convex_polygon(&grid, &[a, nalgebra::center(&a, &b), b], Coverage::Inner);
        prop_assert!(inner.is_empty());
    }

    #[test]
    fn outer_disc_covers_the_disc_and_no_more(
        grid in grids(),
        centre in (-0.2..1.2, -0.2..1.2),
        radius_cells in 0.0..15.0,
        samples in prop::collection::vec((0.0..=1.0, 0.0..std::f64::consts::TAU), 64),
    ) {
        let c = to_world(&grid, centre);
        let r = radius_cells * grid.cell_m;
        let mut set = CellSet::empty(&grid);
        set.fill_disc(&grid, c, r, Coverage::Outer);
        let rim = (0..32).map(|k| (1.0, k as Real * std::f64::consts::TAU / 32.0));
        for (s, a) in samples.iter().copied().chain(rim) {
            let p = c + nalgebra::Vector2::new(a.cos(), a.sin()) * (r * s);
            for cell in cells_containing(&grid, &p) {
                prop_assert!(set.contains(cell), "cell {:?} holds {:?} of the disc", cell, p);
            }
        }
        for cell in set.iter() {
            let sq = grid.cell_rect(cell);
            let near = Point2::new(c.x.clamp(sq.min.x, sq.max.x), c.y.clamp(sq.min.y, sq.max.y));
            prop_assert!((near - c).norm() <= r + TOL, "cell {:?}", cell);
        }
    }

    #[test]
    fn inner_disc_stays_inside_and_keeps_cells_well_inside(
        grid in grids(),
        centre in (-0.2..1.2, -0.2..1.2),
        radius_cells in 0.0..15.0,
    ) {
        let c = to_world(&grid, centre);
        let r = radius_cells * grid.cell_m;
        let mut set = CellSet::empty(&grid);
        set.fill_disc(&grid, c, r, Coverage::Inner);
        for cell in all_cells(&grid) {
            let far = grid
                .cell_rect(cell)
                .corners()
                .iter()
                .map(|p| (p - c).norm())
                .fold(0.0, Real::max);
            if set.contains(cell) {
                prop_assert!(far <= r, "cell {:?} reaches {} > {}", cell, far, r);
            } else {
                prop_assert!(far > r - TOL, "cell {:?} well inside but missing", cell);
            }
        }
    }

    /// Filling discs into a set that already holds cells (where a disc whose square is
    /// already full is skipped) gives the union of those cells and the discs filled alone.
    #[test]
    fn discs_filled_into_a_full_region_add_what_they_add_alone(
        grid in grids(),
        blocks in prop::collection::vec((0.0..1.0, 0.0..1.0, 1u32..20, 1u32..20), 0..4),
        discs in prop::collection::vec(((-0.2..1.2, -0.2..1.2), 0.0..6.0, any::<bool>()), 1..8),
    ) {
        let mut held = CellSet::empty(&grid);
        for &(u, v, w, h) in &blocks {
            let x0 = ((u * grid.nx as Real) as u32).min(grid.nx - 1);
            let y0 = ((v * grid.ny as Real) as u32).min(grid.ny - 1);
            for iy in y0..(y0 + h).min(grid.ny) {
                held.fill_row_span(iy, x0, x0 + w - 1);
            }
        }
        let mut filled = held.clone();
        let mut alone = CellSet::empty(&grid);
        for &(centre, radius_cells, outer) in &discs {
            let c = to_world(&grid, centre);
            let coverage = if outer { Coverage::Outer } else { Coverage::Inner };
            filled.fill_disc(&grid, c, radius_cells * grid.cell_m, coverage);
            alone.fill_disc(&grid, c, radius_cells * grid.cell_m, coverage);
        }
        alone.or_assign(&held);
        prop_assert_eq!(filled, alone);
    }

    /// Every word read through [`CellSet::word_dilation`] (or
    /// [`CellSet::word_dilation_within`] the set's rows) is that word of the whole dilation,
    /// and a word or row it says cannot hold cells ([`sets::raster::WordDilation::may_hold`],
    /// `may_hold_row`) is empty: across word boundaries and grid edges, for empty sets, radii from negative to
    /// past the grid and radii no cell size bounds.
    #[test]
    fn a_dilation_read_word_by_word_is_the_dilation(
        (ox, oy, cell_m) in (-100.0..100.0, -100.0..100.0, 0.1..3.0),
        (nx, ny) in (1u32..260, 1u32..40),
        cells in prop::collection::vec((0.0..1.0, 0.0..1.0), 0..40),
        radius_cells in prop_oneof![
            6 => -1.0..8.0,
            2 => 8.0..200.0,
            1 => Just(Real::NAN),
            1 => Just(Real::INFINITY),
        ],
    ) {
        let grid = GroundGrid { origin: Point2::new(ox, oy), cell_m, nx, ny };
        let set = random_set(&grid, &cells);
        let r = radius_cells * cell_m;
        let whole = set.dilate(&grid, r);
        let mut words = set.word_dilation(&grid, r);
        // Told the rows the set's cells lie in (with a margin), it reads only those rows and
        // must answer the same.
        let held = set.row_range().map_or(0..0, |(a, b)| a.saturating_sub(1)..b + 2);
        let mut within = set.word_dilation_within(&grid, r, held);
        for iy in 0..ny {
            prop_assert!(
                within.may_hold_row(iy) || whole.row(iy).iter().all(|&w| w == 0),
                "row {} radius {} is not empty", iy, r
            );
            for w in 0..set.words_per_row() {
                prop_assert_eq!(
                    words.word(&set, iy, w), whole.row(iy)[w],
                    "row {} word {} radius {}", iy, w, r
                );
                prop_assert_eq!(within.word(&set, iy, w), whole.row(iy)[w]);
                prop_assert_eq!(within.may_hold(iy, w), words.may_hold(iy, w));
                prop_assert!(
                    words.may_hold(iy, w) || whole.row(iy)[w] == 0,
                    "row {} word {} radius {} is not empty", iy, w, r
                );
            }
        }
    }

    #[test]
    fn dilation_reaches_every_point_within_the_radius_and_no_further(
        grid in grids(),
        cells in prop::collection::vec((0.0..1.0, 0.0..1.0), 1..12),
        radius_cells in 0.0..6.0,
        moves in prop::collection::vec(((0.0..=1.0, 0.0..=1.0), 0.0..=1.0, 0.0..std::f64::consts::TAU), 64),
    ) {
        let set = random_set(&grid, &cells);
        let r = radius_cells * grid.cell_m;
        let grown = set.dilate(&grid, r);
        prop_assert!(set.is_subset_of(&grown));
        let members: Vec<CellIndex> = set.iter().collect();
        for (i, ((fx, fy), s, a)) in moves.iter().copied().enumerate() {
            let sq = grid.cell_rect(members[i % members.len()]);
            let start = Point2::new(
                sq.min.x + fx * (sq.max.x - sq.min.x),
                sq.min.y + fy * (sq.max.y - sq.min.y),
            );
            // Full-length moves from the square's corners probe the reach exactly.
            let s = if i % 4 == 0 { 1.0 } else { s };
            let p = start + nalgebra::Vector2::new(a.cos(), a.sin()) * (r * s);
            for c in cells_containing(&grid, &p) {
                prop_assert!(grown.contains(c), "{:?} is within {} of the set", p, r);
            }
        }
        for c in grown.iter() {
            let gap = members.iter().map(|&m| square_gap(c, m, grid.cell_m)).fold(Real::INFINITY, Real::min);
            prop_assert!(gap <= r + TOL, "cell {:?} is {} away, radius {}", c, gap, r);
        }
    }

    #[test]
    fn algebra_agrees_with_a_hash_set(
        grid in grids(),
        a in prop::collection::vec((0.0..1.0, 0.0..1.0), 0..200),
        b in prop::collection::vec((0.0..1.0, 0.0..1.0), 0..200),
        probe in prop::collection::vec((0u32..70, 0u32..70), 32),
        bx in (0u32..70, 0u32..70, 0u32..70, 0u32..70),
    ) {
        let (sa, sb) = (random_set(&grid, &a), random_set(&grid, &b));
        let ma: HashSet<CellIndex> = sa.iter().collect();
        let mb: HashSet<CellIndex> = sb.iter().collect();
        prop_assert_eq!(sa.count() as usize, ma.len());
        let model_a: HashSet<CellIndex> = random_set(&grid, &a).iter().collect();
        prop_assert_eq!(&model_a, &ma);
        for &c in &probe {
            prop_assert_eq!(sa.contains(c), ma.contains(&c));
        }
        let mut and = sa.clone();
        and.and_assign(&sb);
        let mut or = sa.clone();
        or.or_assign(&sb);
        let mut diff = sa.clone();
        diff.and_not_assign(&sb);
        let m_and: HashSet<CellIndex> = ma.intersection(&mb).copied().collect();
        let m_or: HashSet<CellIndex> = ma.union(&mb).copied().collect();
        let m_diff: HashSet<CellIndex> = ma.difference(&mb).copied().collect();
        prop_assert_eq!(and.iter().collect::<HashSet<_>>(), m_and.clone());
        prop_assert_eq!(or.iter().collect::<HashSet<_>>(), m_or);
        prop_assert_eq!(diff.iter().collect::<HashSet<_>>(), m_diff.clone());
        prop_assert_eq!(sa.intersection_count(&sb) as usize, m_and.len());
        prop_assert_eq!(sa.difference_count(&sb) as usize, m_diff.len());
        prop_assert_eq!(sa.intersects(&sb), !m_and.is_empty());
        prop_assert_eq!(sa.is_subset_of(&sb), ma.is_subset(&mb));
        prop_assert!(and.is_subset_of(&sa) && sa.is_subset_of(&or));
        prop_assert_eq!(sa.is_empty(), ma.is_empty());

        // Extent: bounding box, row range, counting in and cropping to a box, barycentre.
        let bbox = sa.bounding_box();
        let model_box = (!ma.is_empty()).then(|| CellBox {
            x0: ma.iter().map(|c| c.0).min().unwrap_or(0),
            y0: ma.iter().map(|c| c.1).min().unwrap_or(0),
            x1: ma.iter().map(|c| c.0).max().unwrap_or(0),
            y1: ma.iter().map(|c| c.1).max().unwrap_or(0),
        });
        prop_assert_eq!(bbox, model_box);
        prop_assert_eq!(sa.row_range(), model_box.map(|b| (b.y0, b.y1)));
        let cb = CellBox { x0: bx.0, y0: bx.1, x1: bx.2, y1: bx.3 };
        let m_in: HashSet<CellIndex> = ma.iter().copied().filter(|&c| cb.contains(c)).collect();
        prop_assert_eq!(sa.count_in_box(&cb) as usize, m_in.len());
        let m_and_in = m_and.iter().filter(|&&c| cb.contains(c)).count();
        prop_assert_eq!(sa.intersection_count_in_box(&sb, &cb) as usize, m_and_in);
        let mut cropped = sa.clone();
        cropped.crop(&cb);
        prop_assert_eq!(cropped.iter().collect::<HashSet<_>>(), m_in);
        match sa.barycentre(&grid) {
            None => prop_assert!(ma.is_empty()),
            Some(p) => {
                let n = ma.len() as Real;
                let mx = ma.iter().map(|&c| grid.cell_centre(c).x).sum::<Real>() / n;
                let my = ma.iter().map(|&c| grid.cell_centre(c).y).sum::<Real>() / n;
                prop_assert!((p.x - mx).abs() < 1e-9 && (p.y - my).abs() < 1e-9);
            }
        }

        // Encoding round-trips.
        let e = sa.encode();
        prop_assert_eq!(sa.encoded_run_count(), e.runs.len());
        prop_assert_eq!(e.bbox, bbox);
        prop_assert_eq!(e.runs.iter().map(|&r| u64::from(r)).sum::<u64>(), bbox.map_or(0, |b| b.cell_count()));
        prop_assert_eq!(CellSet::decode(&grid, &e), Ok(sa.clone()));
    }

    /// The runs counted word by word are the runs written, on grids several words wide, for
    /// sets of spans that start and end anywhere in a word.
    #[test]
    fn the_runs_counted_are_the_runs_encoded(
        (nx, ny) in (1u32..300, 1u32..12),
        spans in prop::collection::vec((0.0..1.0, 0.0..1.0, 0u32..140), 0..12),
    ) {
        let grid = GroundGrid { origin: Point2::origin(), cell_m: 1.0, nx, ny };
        let mut set = CellSet::empty(&grid);
        for (u, v, len) in spans {
            let (x, y) = ((u * Real::from(nx)) as u32, (v * Real::from(ny)) as u32);
            set.fill_row_span(y.min(ny - 1), x, x.saturating_add(len));
        }
        prop_assert_eq!(set.encoded_run_count(), set.encode().runs.len());
    }

    #[test]
    fn decode_of_arbitrary_input_never_panics(
        grid in grids(),
        dn in (-2i64..=2, -2i64..=2),
        bbox in prop::option::of((0u32..80, 0u32..80, 0u32..80, 0u32..80)),
        huge in any::<bool>(),
        runs in prop::collection::vec(prop_oneof![0u32..50, any::<u32>()], 0..40),
    ) {
        let bbox = bbox.map(|(x0, y0, x1, y1)| {
            if huge {
                CellBox { x0, y0, x1: u32::MAX - x1, y1: u32::MAX - y1 }
            } else {
                CellBox { x0, y0, x1, y1 }
            }
        });
        let encoded = EncodedSet {
            nx: (i64::from(grid.nx) + dn.0) as u32,
            ny: (i64::from(grid.ny) + dn.1) as u32,
            bbox,
            runs,
        };
        if let Ok(set) = CellSet::decode(&grid, &encoded) {
            // Whatever is accepted lies in the box and survives a round trip.
            if let (Some(b), Some(got)) = (encoded.bbox, set.bounding_box()) {
                prop_assert!(got.x0 >= b.x0 && got.y0 >= b.y0 && got.x1 <= b.x1 && got.y1 <= b.y1);
            }
            prop_assert_eq!(CellSet::decode(&grid, &set.encode()), Ok(set));
        }
    }

    #[test]
    fn decode_accepts_every_well_formed_run_list(
        grid in grids(),
        bx in (0.0..1.0, 0.0..1.0, 0.0..1.0, 0.0..1.0),
        cuts in prop::collection::vec(0.0..1.0, 0..20),
    ) {
        let (x0, x1) = ((bx.0 * grid.nx as Real) as u32, (bx.1 * grid.nx as Real) as u32);
        let (y0, y1) = ((bx.2 * grid.ny as Real) as u32, (bx.3 * grid.ny as Real) as u32);
        let b = CellBox { x0: x0.min(x1), y0: y0.min(y1), x1: x0.max(x1), y1: y0.max(y1) };
        let total = b.cell_count();
        let mut points: Vec<u64> = cuts.iter().map(|&c| (c * total as Real) as u64).collect();
        points.push(0);
        points.push(total);
        points.sort_unstable();
        let runs: Vec<u32> = points.windows(2).map(|w| (w[1] - w[0]) as u32).collect();
        let encoded = EncodedSet { nx: grid.nx, ny: grid.ny, bbox: Some(b), runs: runs.clone() };
        let set = CellSet::decode(&grid, &encoded);
        prop_assert!(set.is_ok());
        let set = set.unwrap_or_else(|_| CellSet::empty(&grid));
        let full: u64 = runs.iter().skip(1).step_by(2).map(|&r| u64::from(r)).sum();
        prop_assert_eq!(set.count(), full);
        prop_assert_eq!(set.count_in_box(&b), full);
    }
}

/// A grid up to 200 cells wide (rows of several words), a set of scattered cells and row
/// spans on it, and an area of it.
fn coarsening_cases() -> impl Strategy<Value = (GroundGrid, CellSet, CellBox, u32)> {
    (
        1u32..200,
        1u32..40,
        proptest::collection::vec((0u32..200, 0u32..40), 0..120),
        proptest::collection::vec((0u32..200, 0u32..200, 0u32..40), 0..6),
        (0u32..200, 0u32..200, 0u32..40, 0u32..40),
        1u32..12,
    )
        .prop_map(|(nx, ny, cells, spans, (a, b, c, d), factor)| {
            let grid = GroundGrid {
                origin: Point2::new(0.0, 0.0),
                cell_m: 0.5,
                nx,
                ny,
            };
            let mut set = CellSet::empty(&grid);
            for (x, y) in cells {
                set.set((x % nx, y % ny), true);
            }
            for (a, b, y) in spans {
                let (a, b) = (a % nx, b % nx);
                set.fill_row_span(y % ny, a.min(b), a.max(b));
            }
            let (a, b, c, d) = (a % nx, b % nx, c % ny, d % ny);
            let area = CellBox {
                x0: a.min(b),
                x1: a.max(b),
                y0: c.min(d),
                y1: c.max(d),
            };
            (grid, set, area, factor)
        })
}

proptest! {
    /// A block is in the coarsened set exactly when one of its fine cells of the area is in
    /// the set: the coarsening never loses a cell (it stays outer) and adds no block.
    #[test]
    fn coarsening_keeps_a_block_when_any_of_its_cells_is_in_the_set(
        (grid, set, area, factor) in coarsening_cases()
    ) {
        let blocks = GroundGrid {
            origin: grid.origin,
            cell_m: grid.cell_m * f64::from(factor),
            nx: (area.x1 - area.x0 + 1).div_ceil(factor),
            ny: (area.y1 - area.y0 + 1).div_ceil(factor),
        };
        let coarse = set.coarsen_any(&area, factor, &blocks);
        for cy in 0..blocks.ny {
            for cx in 0..blocks.nx {
                let xs = area.x0 + cx * factor..=(area.x0 + (cx + 1) * factor - 1).min(area.x1);
                let ys = area.y0 + cy * factor..=(area.y0 + (cy + 1) * factor - 1).min(area.y1);
                let any = ys.clone().any(|y| xs.clone().any(|x| set.contains((x, y))));
                prop_assert_eq!(coarse.contains((cx, cy)), any, "block {:?}", (cx, cy));
            }
        }
    }
}
