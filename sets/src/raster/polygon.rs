//! Rasterising a convex polygon, row by row.
//!
//! Outer: the polygon's part in a row's closed strip `[y_lo, y_hi]` is a convex polygon whose
//! vertices all lie on the polygon's edges clipped to the strip, so the x-extent of the
//! clipped edges bounds it. The same holds for any polygon (a horizontal line through an
//! interior point meets the boundary on both sides), so `Outer` stays safe even for a
//! non-convex input.
//!
//! Inner: a convex polygon is the intersection of the inner half-planes of its edges; a cell
//! lies inside when its four corners lie in every half-plane, narrowed by the margin. For a
//! non-convex simple polygon this gives the cells inside its kernel, still a subset.

use super::{CellSet, Coverage, grid_scale, margin};
use crate::grid::GroundGrid;
use crate::math::{Point2, Real};

impl CellSet {
    /// Adds the cells of a convex polygon (any orientation; repeated or collinear vertices are
    /// fine) by `coverage`: `Outer` adds every cell whose closed square meets the polygon,
    /// `Inner` only cells whose closed square lies inside it. Geometry is exact up to a
    /// margin of about `1e-9 * (1 + |coordinates|)` that always errs the safe way. Cells
    /// outside the grid are ignored.
    ///
    /// Degenerate shapes: with one or two vertices (a point, a segment) or no area, `Outer`
    /// adds the cells the shape touches and `Inner` adds nothing; an empty slice adds nothing.
    ///
    /// Non-finite vertices: `Inner` adds nothing; `Outer` adds **every cell of the grid**,
    /// because a shape that cannot be bounded is only safely covered by everything (an outer
    /// set that silently lost cells would break the guarantee). Callers that would rather
    /// detect it check [`polygon_is_finite`] first.
    pub fn fill_convex_polygon(
        &mut self,
        grid: &GroundGrid,
        polygon: &[Point2],
        coverage: Coverage,
    ) {
        self.fill_convex_polygon_rows(grid, polygon, coverage, (0, u32::MAX));
    }

    /// [`CellSet::fill_convex_polygon`] in the rows `first..=last` of `rows` only: adds
    /// exactly the cells of those rows it adds, and spends no time on the other rows (for a
    /// caller that needs only some rows of a tall polygon).
    pub fn fill_convex_polygon_rows(
        &mut self,
        grid: &GroundGrid,
        polygon: &[Point2],
        coverage: Coverage,
        rows: (u32, u32),
    ) {
        if polygon.is_empty() {
            return;
        }
        if !polygon_is_finite(polygon) {
            if coverage == Coverage::Outer && self.nx > 0 {
                for iy in rows.0..=rows.1.min(self.ny.saturating_sub(1)) {
                    self.fill_row_span(iy, 0, self.nx - 1);
                }
            }
            return;
        }
        let scale = polygon
            .iter()
            .fold(grid_scale(grid), |m, p| m.max(p.x.abs()).max(p.y.abs()));
        let eps = margin(scale);
        match coverage {
            Coverage::Outer => self.fill_polygon_outer(grid, polygon, eps, rows),
            Coverage::Inner => self.fill_polygon_inner(grid, polygon, eps, rows),
        }
    }

    fn fill_polygon_outer(
        &mut self,
        grid: &GroundGrid,
        polygon: &[Point2],
        eps: Real,
        rows: (u32, u32),
    ) {
        let (y_min, y_max) = polygon
            .iter()
            .fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.y), hi.max(p.y))
            });
        let Some((r0, r1)) = grid
            .rows_touching(y_min - eps, y_max + eps)
            .and_then(|r| within(r, rows))
        else {
            return;
        };
        let rows = (r1 - r0) as usize + 1;
        // Per row, the x-extent of the clipped edges (on the stack for the short polygons
        // most callers fill many of).
        let unset = (Real::INFINITY, Real::NEG_INFINITY);
        let mut short = [unset; SHORT_ROWS];
        let mut tall = Vec::new();
        let extent = if rows <= SHORT_ROWS {
            &mut short[..rows]
        } else {
            tall.resize(rows, unset);
            &mut tall[..]
        };
        let n = polygon.len();
        let grid_rows = grid.rows();
        for i in 0..n {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            let Some((e0, e1)) = grid
                .rows_touching(a.y.min(b.y) - eps, a.y.max(b.y) + eps)
                .and_then(|r| within(r, (r0, r1)))
            else {
                continue;
            };
            for iy in e0..=e1 {
                let strip_lo = grid_rows.edge(iy) - eps;
                let strip_hi = grid_rows.edge(iy + 1) + eps;
                if let Some((lo, hi)) = clipped_x_extent(a, b, strip_lo, strip_hi) {
                    let row = &mut extent[(iy - r0) as usize];
                    *row = (row.0.min(lo), row.1.max(hi));
                }
            }
        }
        let columns = grid.columns();
        for (k, &(lo, hi)) in extent.iter().enumerate() {
            if let Some((c0, c1)) = columns.touching(lo - eps, hi + eps) {
                self.fill_row_span(r0 + k as u32, c0, c1);
            }
        }
    }

    fn fill_polygon_inner(
        &mut self,
        grid: &GroundGrid,
        polygon: &[Point2],
        eps: Real,
        rows: (u32, u32),
    ) {
        if polygon.len() < 3 {
            return;
        }
        // Shoelace about the first vertex keeps the products small.
        let p0 = polygon[0];
        let n = polygon.len();
        let twice_area: Real = (0..n)
            .map(|i| {
                let (a, b) = (polygon[i] - p0, polygon[(i + 1) % n] - p0);
                a.x * b.y - a.y * b.x
            })
            .sum();
        if !(twice_area != 0.0 && twice_area.is_finite()) {
            return;
        }
        // Half-planes `ex * (y - p.y) - ey * (x - p.x) >= eps * |e|`, inside on the left of
        // each edge once oriented counter-clockwise.
        let planes: Vec<HalfPlane> = (0..n)
            .filter_map(|i| {
                let (mut p, mut q) = (polygon[i], polygon[(i + 1) % n]);
                if twice_area < 0.0 {
                    std::mem::swap(&mut p, &mut q);
                }
                let (ex, ey) = (q.x - p.x, q.y - p.y);
                let len = ex.hypot(ey);
                (len > 0.0).then_some(HalfPlane {
                    p,
                    ex,
                    ey,
                    slack: eps * len,
                })
            })
            .collect();
        let (y_min, y_max) = polygon
            .iter()
            .fold((Real::INFINITY, Real::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.y), hi.max(p.y))
            });
        let Some((r0, r1)) = grid
            .rows_touching(y_min, y_max)
            .and_then(|r| within(r, rows))
        else {
            return;
        };
        let (columns, grid_rows) = (grid.columns(), grid.rows());
        for iy in r0..=r1 {
            let (y_lo, y_hi) = (grid_rows.edge(iy), grid_rows.edge(iy + 1));
            let mut lo = Real::NEG_INFINITY;
            let mut hi = Real::INFINITY;
            let mut open = true;
            for h in &planes {
                let y = if h.ex >= 0.0 { y_lo } else { y_hi };
                let g = h.ex * (y - h.p.y) - h.slack;
                let bound = h.p.x + g / h.ey;
                // A NaN (overflow on absurd coordinates) must close the row, not be skipped
                // by `min`/`max`, or the constraint would silently vanish.
                if g.is_nan() || (h.ey != 0.0 && bound.is_nan()) || (h.ey == 0.0 && g < 0.0) {
                    open = false;
                    break;
                }
                if h.ey > 0.0 {
                    hi = hi.min(bound);
                } else if h.ey < 0.0 {
                    lo = lo.max(bound);
                }
            }
            if let Some((c0, c1)) = columns.inside(lo, hi).filter(|_| open) {
                self.fill_row_span(iy, c0, c1);
            }
        }
    }
}

/// Rows of an outer fill whose extents are kept on the stack.
const SHORT_ROWS: usize = 64;

/// The rows of `range` that are also in `window` (both inclusive), if any.
fn within(range: (u32, u32), window: (u32, u32)) -> Option<(u32, u32)> {
    let (a, b) = (range.0.max(window.0), range.1.min(window.1));
    (a <= b).then_some((a, b))
}

/// Whether every vertex of `polygon` has finite coordinates, the condition for
/// [`CellSet::fill_convex_polygon`] to rasterise it rather than fall back.
pub fn polygon_is_finite(polygon: &[Point2]) -> bool {
    polygon.iter().all(|p| p.x.is_finite() && p.y.is_finite())
}

/// One edge's inner half-plane: `ex * (y - p.y) - ey * (x - p.x) >= slack`.
struct HalfPlane {
    p: Point2,
    ex: Real,
    ey: Real,
    slack: Real,
}

/// The x-extent of segment `ab` clipped to the strip `lo <= y <= hi`, `None` if it misses it.
/// An overflowing computation gives the whole line, the safe answer for outer coverage.
fn clipped_x_extent(a: Point2, b: Point2, lo: Real, hi: Real) -> Option<(Real, Real)> {
    let dy = b.y - a.y;
    let (t0, t1) = if dy == 0.0 {
        if a.y < lo || a.y > hi {
            return None;
        }
        (0.0, 1.0)
    } else {
        let (ta, tb) = ((lo - a.y) / dy, (hi - a.y) / dy);
        (ta.min(tb).max(0.0), ta.max(tb).min(1.0))
    };
    if t0 > t1 {
        return None;
    }
    let dx = b.x - a.x;
    let (xa, xb) = (a.x + t0 * dx, a.x + t1 * dx);
    if xa.is_nan() || xb.is_nan() {
        return Some((Real::NEG_INFINITY, Real::INFINITY));
    }
    Some((xa.min(xb), xa.max(xb)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> GroundGrid {
        // Cells of 1 m from (-5, -5): cell (ix, iy) is [ix - 5, ix - 4] x [iy - 5, iy - 4].
        GroundGrid::new(5.0, 1.0)
    }

    fn square(x0: Real, y0: Real, x1: Real, y1: Real) -> Vec<Point2> {
        vec![
            Point2::new(x0, y0),
            Point2::new(x1, y0),
            Point2::new(x1, y1),
            Point2::new(x0, y1),
        ]
    }

    fn filled(poly: &[Point2], coverage: Coverage) -> Vec<(u32, u32)> {
        let g = grid();
        let mut s = CellSet::empty(&g);
        s.fill_convex_polygon(&g, poly, coverage);
        s.iter().collect()
    }

    #[test]
    fn polygon_on_cell_boundaries_touches_neighbours_outer_and_leaves_flush_cells_inner() {
        let sq = square(-3.0, -3.0, -1.0, -1.0);
        // Closed squares sharing an edge or a corner with the polygon meet it.
        let outer = filled(&sq, Coverage::Outer);
        assert_eq!(outer.len(), 16);
        assert!(outer.contains(&(1, 1)) && outer.contains(&(4, 4)));
        assert!(!outer.contains(&(0, 0)));
        // Inner narrows by the margin: cells flush with the edges are inside only up to
        // rounding, so they are not claimed; a hair more and they are.
        assert!(filled(&sq, Coverage::Inner).is_empty());
        let grown = square(-3.0 - 1e-6, -3.0 - 1e-6, -1.0 + 1e-6, -1.0 + 1e-6);
        assert_eq!(
            filled(&grown, Coverage::Inner),
            vec![(2, 2), (3, 2), (2, 3), (3, 3)]
        );
    }

    #[test]
    fn orientation_and_repeated_or_collinear_vertices_do_not_matter() {
        let ccw = square(-3.0, -3.0, -1.0, -1.0);
        let mut cw = ccw.clone();
        cw.reverse();
        let mut messy = vec![ccw[0], ccw[0], Point2::new(-2.0, -3.0), ccw[1]];
        messy.extend_from_slice(&ccw[2..]);
        messy.push(ccw[3]);
        for cov in [Coverage::Inner, Coverage::Outer] {
            assert_eq!(filled(&cw, cov), filled(&ccw, cov));
            assert_eq!(filled(&messy, cov), filled(&ccw, cov));
        }
    }

    #[test]
    fn edge_shared_by_two_cells_adds_both_outer_and_neither_inner() {
        // The segment x = 0 between columns 4 and 5, inside row 5.
        let seg = vec![Point2::new(0.0, 0.25), Point2::new(0.0, 0.75)];
        assert_eq!(filled(&seg, Coverage::Outer), vec![(4, 5), (5, 5)]);
        assert!(filled(&seg, Coverage::Inner).is_empty());
        let point = vec![Point2::new(0.0, 0.0)];
        assert_eq!(
            filled(&point, Coverage::Outer),
            vec![(4, 4), (5, 4), (4, 5), (5, 5)]
        );
        let flat = vec![
            Point2::new(-1.5, 0.5),
            Point2::new(0.5, 0.5),
            Point2::new(2.5, 0.5),
        ];
        assert_eq!(filled(&flat, Coverage::Outer).len(), 5);
        assert!(filled(&flat, Coverage::Inner).is_empty());
    }

    #[test]
    fn polygon_past_the_grid_edges_is_clamped() {
        let big = square(-100.0, -100.0, 100.0, 100.0);
        assert_eq!(filled(&big, Coverage::Inner).len(), 100);
        assert_eq!(filled(&big, Coverage::Outer).len(), 100);
        let corner = square(4.5, 4.5, 50.0, 50.0);
        assert_eq!(filled(&corner, Coverage::Outer), vec![(9, 9)]);
        assert!(filled(&corner, Coverage::Inner).is_empty());
        let outside = square(6.0, 6.0, 9.0, 9.0);
        assert!(filled(&outside, Coverage::Outer).is_empty());
        // The grid's own edge x = 5 touches the last column.
        let on_edge = square(5.0, -1.0, 7.0, 1.0);
        assert_eq!(
            filled(&on_edge, Coverage::Outer),
            vec![(9, 3), (9, 4), (9, 5), (9, 6)]
        );
    }

    #[test]
    fn non_finite_vertices_fill_everything_outer_and_nothing_inner() {
        let mut tri = vec![
            Point2::new(0.0, 0.0),
            Point2::new(1.0, 0.0),
            Point2::new(0.0, 1.0),
        ];
        tri[1].x = Real::NAN;
        assert!(!polygon_is_finite(&tri));
        assert_eq!(filled(&tri, Coverage::Outer).len(), 100);
        assert!(filled(&tri, Coverage::Inner).is_empty());
        tri[1].x = Real::INFINITY;
        assert_eq!(filled(&tri, Coverage::Outer).len(), 100);
        assert!(filled(&[], Coverage::Outer).is_empty());
    }

    #[test]
    fn triangle_inner_keeps_only_cells_strictly_below_the_diagonal() {
        // Legs outside the grid; the hypotenuse x + y = -6 + shift meets the upper-right
        // corners (ix - 4, iy - 4) of the cells with ix + iy = 2 when shift is 0.
        let tri = |shift: Real| {
            vec![
                Point2::new(-6.0, -6.0),
                Point2::new(shift, -6.0),
                Point2::new(-6.0, shift),
            ]
        };
        let below = |n: u32| -> Vec<(u32, u32)> {
            (0..10u32)
                .flat_map(|iy| (0..10u32).map(move |ix| (ix, iy)))
                .filter(|&(ix, iy)| ix + iy <= n)
                .collect()
        };
        assert_eq!(filled(&tri(0.0), Coverage::Inner), below(1));
        assert_eq!(filled(&tri(1e-6), Coverage::Inner), below(2));
        // Outer: lower-left corners (ix - 5, iy - 5) reach the closed triangle for ix + iy <= 4.
        assert_eq!(filled(&tri(0.0), Coverage::Outer), below(4));
    }

    #[test]
    fn columns_inside_uses_the_grid_edges() {
        let columns = grid().columns();
        assert_eq!(columns.inside(-5.0, -4.0), Some((0, 0)));
        assert_eq!(columns.inside(-5.0, -4.0 - 1e-12), None);
        assert_eq!(columns.inside(-4.5, 0.0), Some((1, 4)));
        assert_eq!(columns.inside(-1e9, 1e9), Some((0, 9)));
        assert_eq!(columns.inside(Real::NAN, 1.0), None);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]

        /// Filling some rows adds exactly the cells of those rows that filling all adds.
        #[test]
        fn filling_some_rows_adds_those_rows_of_the_whole_fill(
            points in proptest::collection::vec((-7.0f64..7.0, -7.0f64..7.0), 1..7),
            outer: bool,
            infinite: bool,
            a in 0u32..12,
            b in 0u32..12,
        ) {
            let g = grid();
            let mut polygon: Vec<Point2> = points.iter().map(|&(x, y)| Point2::new(x, y)).collect();
            if infinite {
                polygon[0].x = Real::INFINITY;
            }
            let coverage = if outer { Coverage::Outer } else { Coverage::Inner };
            let rows = (a.min(b), a.max(b));
            let mut all = CellSet::empty(&g);
            all.fill_convex_polygon(&g, &polygon, coverage);
            let mut some = CellSet::empty(&g);
            some.fill_convex_polygon_rows(&g, &polygon, coverage, rows);
            for iy in 0..g.ny {
                let expected: &[u64] = if (rows.0..=rows.1).contains(&iy) { all.row(iy) } else { &[0] };
                proptest::prop_assert_eq!(some.row(iy), expected, "row {}", iy);
            }
        }
    }
}
