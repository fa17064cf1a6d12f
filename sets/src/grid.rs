//! The ground grid every set lives on, shared by every process.
//!
//! Square cells of side `cell_m` tile the region of interest `[-h, h]^2` from its south-west
//! corner; cell `(ix, iy)` covers `[x0 + ix*d, x0 + (ix+1)*d] x [y0 + iy*d, y0 + (iy+1)*d]`.

use serde::{Deserialize, Serialize};

use crate::math::{Point2, Real, floor_fast};

/// A cell index: column `ix` (east), row `iy` (north).
pub type CellIndex = (u32, u32);

/// The ground grid: origin at the RoI's south-west corner, `nx x ny` square cells.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundGrid {
    /// South-west corner of cell `(0, 0)`.
    pub origin: Point2,
    /// Cell side, metres.
    pub cell_m: Real,
    /// Cells along x.
    pub nx: u32,
    /// Cells along y.
    pub ny: u32,
}

/// An axis-aligned rectangle on the ground.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rect {
    /// South-west corner.
    pub min: Point2,
    /// North-east corner.
    pub max: Point2,
}

impl Rect {
    /// Whether `p` lies in the closed rectangle.
    pub fn contains(&self, p: &Point2) -> bool {
        p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y
    }

    /// The four corners, counter-clockwise from the south-west one.
    pub fn corners(&self) -> [Point2; 4] {
        [
            self.min,
            Point2::new(self.max.x, self.min.y),
            self.max,
            Point2::new(self.min.x, self.max.y),
        ]
    }
}

impl GroundGrid {
    /// The grid over `[-half_extent_m, half_extent_m]^2` with cells of side `cell_m`
    /// (the last row and column may reach past the RoI when `cell_m` does not divide it).
    pub fn new(half_extent_m: Real, cell_m: Real) -> Self {
        let n = ((2.0 * half_extent_m / cell_m) - 1e-9).ceil().max(1.0) as u32;
        Self {
            origin: Point2::new(-half_extent_m, -half_extent_m),
            cell_m,
            nx: n,
            ny: n,
        }
    }

    /// Total number of cells.
    pub fn cell_count(&self) -> usize {
        self.nx as usize * self.ny as usize
    }

    /// Area of one cell, m².
    pub fn cell_area(&self) -> Real {
        self.cell_m * self.cell_m
    }

    /// Area covered by the grid, m².
    pub fn area(&self) -> Real {
        self.cell_count() as Real * self.cell_area()
    }

    /// The rectangle covered by the grid.
    pub fn bounds(&self) -> Rect {
        Rect {
            min: self.origin,
            max: Point2::new(
                self.origin.x + self.nx as Real * self.cell_m,
                self.origin.y + self.ny as Real * self.cell_m,
            ),
        }
    }

    /// The cell containing `p` (cells are half-open `[lo, hi)`), or `None` outside the grid.
    pub fn cell_of(&self, p: &Point2) -> Option<CellIndex> {
        let fx = ((p.x - self.origin.x) / self.cell_m).floor();
        let fy = ((p.y - self.origin.y) / self.cell_m).floor();
        if fx >= 0.0 && fy >= 0.0 && fx < self.nx as Real && fy < self.ny as Real {
            Some((fx as u32, fy as u32))
        } else {
            None
        }
    }

    /// The rectangle of cell `(ix, iy)`.
    pub fn cell_rect(&self, (ix, iy): CellIndex) -> Rect {
        let min = Point2::new(
            self.origin.x + ix as Real * self.cell_m,
            self.origin.y + iy as Real * self.cell_m,
        );
        Rect {
            min,
            max: Point2::new(min.x + self.cell_m, min.y + self.cell_m),
        }
    }

    /// Centre of cell `(ix, iy)`.
    pub fn cell_centre(&self, (ix, iy): CellIndex) -> Point2 {
        Point2::new(
            self.origin.x + (ix as Real + 0.5) * self.cell_m,
            self.origin.y + (iy as Real + 0.5) * self.cell_m,
        )
    }

    /// The range of cell columns whose closed extent meets `[x_lo, x_hi]`, clamped to the grid
    /// (`None` if empty). Useful for outer rasterisation.
    pub fn columns_touching(&self, x_lo: Real, x_hi: Real) -> Option<(u32, u32)> {
        self.columns().touching(x_lo, x_hi)
    }

    /// As [`GroundGrid::columns_touching`], for rows and `y`.
    pub fn rows_touching(&self, y_lo: Real, y_hi: Real) -> Option<(u32, u32)> {
        self.rows().touching(y_lo, y_hi)
    }

    /// The columns, for many range queries along x ([`GridAxis`]).
    pub fn columns(&self) -> GridAxis {
        GridAxis::new(self.origin.x, self.cell_m, self.nx)
    }

    /// The rows, for many range queries along y ([`GridAxis`]).
    pub fn rows(&self) -> GridAxis {
        GridAxis::new(self.origin.y, self.cell_m, self.ny)
    }
}

/// One axis of a [`GroundGrid`] (its columns or its rows), made once for many range queries,
/// as rasterising a shape row by row asks: each range is estimated with the reciprocal of the
/// cell size (a product, not a division) and then settled on the exact cell edges
/// `origin + k cell_m` the grid uses, so the answers do not depend on the estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridAxis {
    origin: Real,
    cell_m: Real,
    per_m: Real,
    n: u32,
}

impl GridAxis {
    fn new(origin: Real, cell_m: Real, n: u32) -> Self {
        Self {
            origin,
            cell_m,
            per_m: 1.0 / cell_m,
            n,
        }
    }

    /// Where cell `k` starts (and cell `k - 1` ends): `origin + k cell_m`, the edges every
    /// raster fill of the grid uses.
    pub fn edge(&self, k: u32) -> Real {
        self.origin + k as Real * self.cell_m
    }

    /// `floor((v - origin) / cell_m)`, up to one either way.
    fn estimate(&self, v: Real) -> Real {
        floor_fast((v - self.origin) * self.per_m)
    }

    /// The cells whose closed extent meets `[lo, hi]`, clamped to the axis (`None` if
    /// empty).
    pub fn touching(&self, lo: Real, hi: Real) -> Option<(u32, u32)> {
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return None;
        }
        // A cell [k d, (k+1) d] touches [lo, hi] when k d <= hi and (k+1) d >= lo. The
        // estimates start below the first such cell and above the last (each is off by at
        // most one, one more for the product), and settle towards them.
        let k0 = (self.estimate(lo) - 2.0).max(0.0);
        let k1 = (self.estimate(hi) + 2.0).min(self.n as Real - 1.0);
        if k0 > k1 {
            return None;
        }
        let (mut a, mut b) = (k0 as u32, k1 as u32);
        while a <= b && self.edge(a + 1) < lo {
            a += 1;
        }
        while b >= a && self.edge(b) > hi {
            if b == 0 {
                return None;
            }
            b -= 1;
        }
        (a <= b).then_some((a, b))
    }

    /// The cells whose closed extent lies inside `[lo, hi]`, clamped to the axis (`None` if
    /// none). Useful for inner rasterisation.
    pub fn inside(&self, lo: Real, hi: Real) -> Option<(u32, u32)> {
        if lo.is_nan() || hi.is_nan() || lo > hi || self.n == 0 {
            return None;
        }
        let last = self.n as Real - 1.0;
        // Estimate, then settle on the exact edges, in both directions.
        let mut a = (-floor_fast(-((lo - self.origin) * self.per_m))).clamp(0.0, last) as u32;
        let mut b = (self.estimate(hi) - 1.0).clamp(0.0, last) as u32;
        while a > 0 && self.edge(a - 1) >= lo {
            a -= 1;
        }
        while a < self.n && self.edge(a) < lo {
            a += 1;
        }
        while b + 1 < self.n && self.edge(b + 2) <= hi {
            b += 1;
        }
        while self.edge(b + 1) > hi {
            if b == 0 {
                return None;
            }
            b -= 1;
        }
        (a <= b).then_some((a, b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_grid_is_1000_by_1000() {
        let g = GroundGrid::new(250.0, 0.5);
        assert_eq!((g.nx, g.ny), (1000, 1000));
        assert_eq!(g.cell_of(&Point2::new(-250.0, -250.0)), Some((0, 0)));
        assert_eq!(g.cell_of(&Point2::new(249.99, 249.99)), Some((999, 999)));
        assert_eq!(g.cell_of(&Point2::new(250.0, 0.0)), None);
        assert!((g.area() - 250_000.0).abs() < 1e-6);
    }

    #[test]
    fn touching_includes_shared_edges() {
        let g = GroundGrid::new(5.0, 1.0);
        // x = -4.0 is the edge between columns 0 and 1: both touch.
        assert_eq!(g.columns_touching(-4.0, -4.0), Some((0, 1)));
        assert_eq!(g.columns_touching(-4.5, -4.2), Some((0, 0)));
        assert_eq!(g.columns_touching(-20.0, -10.0), None);
        assert_eq!(g.columns_touching(4.5, 30.0), Some((9, 9)));
    }

    /// The definitions, cell by cell, on the exact edges `origin + k cell_m`.
    fn by_definition(axis: &GridAxis, keep: impl Fn(Real, Real) -> bool) -> Option<(u32, u32)> {
        let cells: Vec<u32> = (0..axis.n)
            .filter(|&k| keep(axis.edge(k), axis.edge(k + 1)))
            .collect();
        Some((*cells.first()?, *cells.last()?))
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(512))]

        /// The ranges an axis finds from its product estimates are the cells the definitions
        /// give: ends exactly on cell edges, a hair either side of them, inside, across and
        /// outside the grid, on grids of odd origins and cell sizes.
        #[test]
        fn axis_ranges_are_the_definitions(
            origin in -300.0f64..300.0,
            cell_m in proptest::prop_oneof![0.05f64..5.0, proptest::strategy::Just(0.1), proptest::strategy::Just(0.3)],
            n in 0u32..60,
            (k_lo, k_hi) in (-5i32..70, -5i32..70),
            (t_lo, t_hi) in (0usize..5, 0usize..5),
        ) {
            let axis = GridAxis::new(origin, cell_m, n);
            // Ends on an edge, a relative hair off it, or between edges.
            let end = |k: i32, t: usize| {
                let e = origin + Real::from(k) * cell_m;
                [e, e.next_up(), e.next_down(), e + 0.37 * cell_m, e - 0.61 * cell_m][t]
            };
            let (lo, hi) = (end(k_lo, t_lo), end(k_hi, t_hi));
            let touching = by_definition(&axis, |a, b| a <= hi && b >= lo).filter(|_| lo <= hi);
            let inside = by_definition(&axis, |a, b| a >= lo && b <= hi).filter(|_| lo <= hi);
            proptest::prop_assert_eq!(axis.touching(lo, hi), touching);
            proptest::prop_assert_eq!(axis.inside(lo, hi), inside);
        }
    }
}
