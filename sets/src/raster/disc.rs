//! Rasterising a closed disc, row by row.
//!
//! In a row's strip `[y_lo, y_hi]` the disc's x-extent is widest at the strip's point nearest
//! the centre (outer) and narrowest at its farthest edge (inner). Half-widths are computed as
//! `sqrt((r - dy) (r + dy))`, which keeps its relative accuracy where `r² - dy²` would cancel.

use super::{CellSet, Coverage, grid_scale, margin};
use crate::grid::GroundGrid;
use crate::math::{Point2, Real};

impl CellSet {
    /// Adds the cells of the closed disc of `radius` around `centre` by `coverage` (see
    /// [`Coverage`]), up to a margin that errs the safe way; cells outside the grid are
    /// ignored. A radius of 0 is a point: `Outer` adds the cells touching it, `Inner` nothing.
    /// A negative radius is the empty shape and adds nothing.
    ///
    /// Non-finite input (a centre or radius that is NaN or infinite) adds nothing for `Inner`
    /// and **every cell of the grid** for `Outer`, the only safe cover of an unbounded shape.
    pub fn fill_disc(
        &mut self,
        grid: &GroundGrid,
        centre: Point2,
        radius: Real,
        coverage: Coverage,
    ) {
        if radius < 0.0 {
            return;
        }
        let finite = centre.x.is_finite() && centre.y.is_finite() && radius.is_finite();
        if !finite {
            if coverage == Coverage::Outer {
                self.fill_all();
            }
            return;
        }
        let scale = grid_scale(grid)
            .max(centre.x.abs() + radius)
            .max(centre.y.abs() + radius);
        let eps = margin(scale);
        match coverage {
            Coverage::Outer => self.fill_disc_outer(grid, centre, radius + eps, eps),
            Coverage::Inner => self.fill_disc_inner(grid, centre, radius - eps, eps),
        }
    }

    fn fill_disc_outer(&mut self, grid: &GroundGrid, c: Point2, r: Real, eps: Real) {
        let Some((r0, r1)) = grid.rows_touching(c.y - r, c.y + r) else {
            return;
        };
        let (columns, grid_rows) = (grid.columns(), grid.rows());
        for iy in r0..=r1 {
            let (y_lo, y_hi) = (grid_rows.edge(iy), grid_rows.edge(iy + 1));
            let dy = (c.y - c.y.clamp(y_lo, y_hi)).abs();
            if dy > r {
                continue;
            }
            let w = ((r - dy) * (r + dy)).sqrt();
            if let Some((c0, c1)) = columns.touching(c.x - w - eps, c.x + w + eps) {
                self.fill_row_span(iy, c0, c1);
            }
        }
    }

    fn fill_disc_inner(&mut self, grid: &GroundGrid, c: Point2, r: Real, eps: Real) {
        if r.is_nan() || r <= 0.0 {
            return;
        }
        let Some((r0, r1)) = grid.rows_touching(c.y - r, c.y + r) else {
            return;
        };
        // Every cell filled below lies inside the disc's bounding square, so touches it: when
        // the set already holds every cell touching the square, nothing would change (the
        // many overlapping discs of one obstacle mostly end here).
        let (columns, grid_rows) = (grid.columns(), grid.rows());
        if let Some((c0, c1)) = columns.touching(c.x - r, c.x + r)
            && (r0..=r1).all(|iy| self.row_span_is_full(iy, c0, c1))
        {
            return;
        }
        for iy in r0..=r1 {
            let (y_lo, y_hi) = (grid_rows.edge(iy), grid_rows.edge(iy + 1));
            let dy = (c.y - y_lo).abs().max((c.y - y_hi).abs());
            if dy >= r {
                continue;
            }
            let w = ((r - dy) * (r + dy)).sqrt();
            if let Some((c0, c1)) = columns.inside(c.x - w + eps, c.x + w - eps) {
                self.fill_row_span(iy, c0, c1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(centre: Point2, radius: Real, coverage: Coverage) -> Vec<(u32, u32)> {
        let g = GroundGrid::new(5.0, 1.0);
        let mut s = CellSet::empty(&g);
        s.fill_disc(&g, centre, radius, coverage);
        s.iter().collect()
    }

    #[test]
    fn radius_zero_on_a_cell_corner_touches_four_cells() {
        let at_corner = filled(Point2::new(0.0, 0.0), 0.0, Coverage::Outer);
        assert_eq!(at_corner, vec![(4, 4), (5, 4), (4, 5), (5, 5)]);
        assert!(filled(Point2::new(0.0, 0.0), 0.0, Coverage::Inner).is_empty());
        assert_eq!(
            filled(Point2::new(0.5, 0.5), 0.0, Coverage::Outer),
            vec![(5, 5)]
        );
        assert!(filled(Point2::new(0.5, 0.5), -1.0, Coverage::Outer).is_empty());
    }

    #[test]
    fn disc_through_cell_corners_excludes_them_inner_and_includes_neighbours_outer() {
        // Radius sqrt(2) about a grid node passes exactly through the corners of the 2x2
        // block around it: the block is inside only up to rounding, so it must not be claimed.
        let c = Point2::new(0.0, 0.0);
        let r = 2.0_f64.sqrt();
        assert!(filled(c, r, Coverage::Inner).is_empty());
        assert_eq!(filled(c, r + 1e-6, Coverage::Inner).len(), 4);
        // Outer: the 2x2 block plus the cells the disc reaches beyond x = +-1 or y = +-1.
        let outer = filled(c, 1.0, Coverage::Outer);
        assert_eq!(outer.len(), 16 - 4);
        assert!(!outer.contains(&(3, 3)));
    }

    #[test]
    fn disc_past_the_grid_is_clamped_and_non_finite_is_safe() {
        assert_eq!(
            filled(Point2::new(0.0, 0.0), 100.0, Coverage::Inner).len(),
            100
        );
        assert!(filled(Point2::new(20.0, 0.0), 3.0, Coverage::Outer).is_empty());
        assert_eq!(
            filled(Point2::new(Real::NAN, 0.0), 1.0, Coverage::Outer).len(),
            100
        );
        assert!(filled(Point2::new(0.0, 0.0), Real::INFINITY, Coverage::Inner).is_empty());
    }
}
