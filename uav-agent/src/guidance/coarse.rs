//! The coarse planning grid: a planner weighs hundreds of predicted sets per decision, so the
//! `setfleet` planner (and the paper's MPC with `guidance.set_resolution = "planning"`) plans
//! on cells a whole number of times larger than the estimator's. A coarse cell belongs to a
//! set when any of its fine cells does (the planning sets stay outer). The paper's MPC by
//! default predicts on the estimator's cells themselves ([`CoarseGrid::identity`]; why counts
//! per coarse cell cannot replace that is in [`paper`](super::paper)'s docs).
//!
//! Where an area must not be invented by the coarsening, a fine set is also counted per coarse
//! cell ([`CoarseGrid::weights`]): [`CellWeights`] holds how many fine cells of each coarse cell
//! a set has, so the area of that set inside any coarse set is measured at the fine resolution.

use sets::grid::GroundGrid;
use sets::raster::{CellBox, CellSet};

/// Side the planning cells aim for, metres.
pub const PLANNING_CELL_M: f64 = 2.5;

/// A fine grid and the coarse grid made of `factor x factor` blocks of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoarseGrid {
    /// The estimator's grid.
    pub fine: GroundGrid,
    /// The planning grid.
    pub coarse: GroundGrid,
    /// Fine cells per coarse cell side.
    pub factor: u32,
}

impl CoarseGrid {
    /// The coarse grid closest to [`PLANNING_CELL_M`] with a whole `factor` (at least 1).
    pub fn new(fine: GroundGrid) -> Self {
        let factor = (PLANNING_CELL_M / fine.cell_m).round().max(1.0) as u32;
        let coarse = GroundGrid {
            origin: fine.origin,
            cell_m: fine.cell_m * factor as f64,
            nx: fine.nx.div_ceil(factor),
            ny: fine.ny.div_ceil(factor),
        };
        Self {
            fine,
            coarse,
            factor,
        }
    }

    /// The grid pair whose coarse grid is `fine` itself (`factor` 1): the paper's MPC at the
    /// estimator's resolution (`guidance.set_resolution = "estimator"`), for which
    /// [`CoarseGrid::downsample`] is the identity and [`CoarseGrid::weights`] counts each cell
    /// once.
    pub fn identity(fine: GroundGrid) -> Self {
        Self {
            fine,
            coarse: fine,
            factor: 1,
        }
    }

    /// The coarse set of every coarse cell holding a cell of `fine_set`
    /// ([`CellSet::coarsen_any`] over the whole fine grid; a copy when `factor` is 1).
    pub fn downsample(&self, fine_set: &CellSet) -> CellSet {
        if self.factor == 1 {
            return fine_set.clone();
        }
        let whole = CellBox {
            x0: 0,
            y0: 0,
            x1: self.fine.nx - 1,
            y1: self.fine.ny - 1,
        };
        fine_set.coarsen_any(&whole, self.factor, &self.coarse)
    }

    /// How many cells of `fine_set` each coarse cell holds, as [`CellWeights`].
    pub fn weights(&self, fine_set: &CellSet) -> CellWeights {
        if self.factor == 1 {
            // Every count is 0 or 1: the one plane is the set.
            return CellWeights {
                planes: if fine_set.is_empty() {
                    Vec::new()
                } else {
                    vec![fine_set.clone()]
                },
                unit_m2: self.fine.cell_area(),
            };
        }
        let f = self.factor as usize;
        let nx = self.coarse.nx as usize;
        let mut counts = vec![0u32; nx * self.coarse.ny as usize];
        for fy in 0..self.fine.ny {
            let row = &mut counts[(fy / self.factor) as usize * nx..][..nx];
            for (w, &word) in fine_set.row(fy).iter().enumerate() {
                let mut bits = word;
                while bits != 0 {
                    let b = bits.trailing_zeros() as usize;
                    if let Some(count) = row.get_mut((w * 64 + b) / f) {
                        *count += 1;
                    }
                    bits &= bits - 1;
                }
            }
        }
        let most = counts.iter().copied().max().unwrap_or(0);
        let planes = (0..u32::BITS - most.leading_zeros())
            .map(|bit| {
                let mut plane = CellSet::empty(&self.coarse);
                for (i, _) in counts
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| *c >> bit & 1 == 1)
                {
                    plane.set(((i % nx) as u32, (i / nx) as u32), true);
                }
                plane
            })
            .collect();
        CellWeights {
            planes,
            unit_m2: self.fine.cell_area(),
        }
    }
}

/// A whole number of fine cells per coarse cell, stored as bit planes (plane `b` holds the
/// coarse cells whose count has bit `b` set), so that the fine area inside a coarse set costs
/// one intersection count per plane.
#[derive(Clone, Debug, PartialEq)]
pub struct CellWeights {
    planes: Vec<CellSet>,
    /// Area of one counted cell, m².
    unit_m2: f64,
}

impl CellWeights {
    /// Every cell of `coarse_set` counted once, as a cell of its own grid: the area of a coarse
    /// set inside `coarse_set` at the coarse resolution.
    pub fn whole(coarse_set: CellSet, cell_area_m2: f64) -> Self {
        Self {
            planes: vec![coarse_set],
            unit_m2: cell_area_m2,
        }
    }

    /// The counted area inside `coarse_set`: the sum of the counts of its cells times the
    /// area of one counted cell, m².
    pub fn area_in(&self, coarse_set: &CellSet) -> f64 {
        let cells: u64 = self
            .planes
            .iter()
            .enumerate()
            .map(|(bit, plane)| coarse_set.intersection_count(plane) << bit)
            .sum();
        cells as f64 * self.unit_m2
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// A coarse cell is in the downsampled set exactly when one of its fine cells is in
        /// the fine set, for any cell size (whole factors, partial blocks at the far edges).
        #[test]
        fn downsample_matches_the_block_definition(
            half in 3.0f64..30.0,
            cell in prop_oneof![Just(0.5), Just(0.3), Just(0.1), Just(0.02), Just(2.5), Just(4.0)],
            cells in proptest::collection::vec((0u32..6000, 0u32..6000), 0..400),
            rows in proptest::collection::vec((0u32..6000, 0u32..6000, 0u32..6000), 0..20),
        ) {
            let fine = GroundGrid::new(half, cell);
            let cg = CoarseGrid::new(fine);
            let mut s = CellSet::empty(&fine);
            for (x, y) in cells {
                s.set((x % fine.nx, y % fine.ny), true);
            }
            for (y, a, b) in rows {
                let (a, b) = (a % fine.nx, b % fine.nx);
                s.fill_row_span(y % fine.ny, a.min(b), a.max(b));
            }
            let d = cg.downsample(&s);
            for cy in 0..cg.coarse.ny {
                for cx in 0..cg.coarse.nx {
                    let f = cg.factor;
                    let any = (cy * f..((cy + 1) * f).min(fine.ny))
                        .any(|fy| (cx * f..((cx + 1) * f).min(fine.nx)).any(|fx| s.contains((fx, fy))));
                    prop_assert_eq!(d.contains((cx, cy)), any, "cell {:?}", (cx, cy));
                }
            }
        }
    }

    /// The weighted area of a fine set inside a coarse set is the area of the fine cells of
    /// the set that lie in the coarse set's cells, exactly.
    #[test]
    fn weights_count_the_fine_cells_of_each_coarse_cell() {
        let fine = GroundGrid::new(25.0, 0.5);
        let cg = CoarseGrid::new(fine);
        let mut s = CellSet::empty(&fine);
        // 25 cells in coarse cell (0, 0), 1 in (1, 0), 3 in (19, 19).
        for x in 0..5 {
            for y in 0..5 {
                s.set((x, y), true);
            }
        }
        for &c in &[(5, 0), (99, 99), (95, 95), (97, 96)] {
            s.set(c, true);
        }
        let w = cg.weights(&s);
        let mut coarse = CellSet::empty(&cg.coarse);
        assert_eq!(w.area_in(&coarse), 0.0);
        coarse.set((0, 0), true);
        assert_eq!(w.area_in(&coarse), 25.0 * 0.25);
        coarse.set((1, 0), true);
        coarse.set((19, 19), true);
        coarse.set((7, 7), true);
        assert_eq!(w.area_in(&coarse), 29.0 * 0.25);
        assert_eq!(
            w.area_in(&CellSet::full(&cg.coarse)),
            s.count() as f64 * 0.25
        );
        // Counted whole, a coarse set is its cells' area.
        let whole = CellWeights::whole(cg.downsample(&s), cg.coarse.cell_area());
        assert_eq!(whole.area_in(&coarse), 3.0 * 6.25);
    }

    /// At factor 1 the coarse grid is the fine one: downsampling copies, and the weights
    /// count every cell once, as the general count would.
    #[test]
    fn the_identity_pair_keeps_every_cell() {
        let fine = GroundGrid::new(25.0, 0.5);
        let id = CoarseGrid::identity(fine);
        assert_eq!(id.coarse, fine);
        let mut s = CellSet::empty(&fine);
        for &c in &[(0, 0), (4, 4), (5, 0), (63, 10), (64, 10), (99, 99)] {
            s.set(c, true);
        }
        assert_eq!(id.downsample(&s), s);
        let mut probe = CellSet::empty(&fine);
        probe.set((4, 4), true);
        probe.set((64, 10), true);
        probe.set((50, 50), true);
        assert_eq!(id.weights(&s).area_in(&probe), 2.0 * 0.25);
        assert_eq!(id.weights(&s).area_in(&CellSet::full(&fine)), 6.0 * 0.25);
        assert_eq!(id.weights(&CellSet::empty(&fine)).area_in(&probe), 0.0);
    }

    #[test]
    fn downsample_marks_blocks_with_any_cell() {
        let fine = GroundGrid::new(25.0, 0.5);
        let cg = CoarseGrid::new(fine);
        assert_eq!(cg.factor, 5);
        assert_eq!(cg.coarse.nx, 20);
        let mut s = CellSet::empty(&fine);
        for &c in &[(0, 0), (4, 4), (5, 0), (63, 10), (64, 10), (99, 99)] {
            s.set(c, true);
        }
        let d = cg.downsample(&s);
        let mut cells: Vec<_> = d.iter().collect();
        cells.sort();
        let mut expected = vec![(0, 0), (1, 0), (12, 2), (19, 19)];
        expected.sort();
        assert_eq!(cells, expected);
    }
}
