//! The coarse planning grid: the MPC weighs hundreds of predicted sets per decision, so it
//! plans on cells a whole number of times larger than the estimator's. A coarse cell belongs
//! to a set when any of its fine cells does (the planning sets stay outer).

use protocol::grid::GroundGrid;
use protocol::raster::CellSet;

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

    /// The coarse set of every coarse cell holding a cell of `fine_set`.
    pub fn downsample(&self, fine_set: &CellSet) -> CellSet {
        let mut out = CellSet::empty(&self.coarse);
        let f = self.factor as usize;
        let mut coarse_row = vec![false; self.coarse.nx as usize];
        for cy in 0..self.coarse.ny {
            coarse_row.iter_mut().for_each(|b| *b = false);
            let y0 = cy * self.factor;
            let y1 = (y0 + self.factor).min(self.fine.ny);
            let mut any = false;
            for fy in y0..y1 {
                for (w, &word) in fine_set.row(fy).iter().enumerate() {
                    let mut bits = word;
                    while bits != 0 {
                        let b = bits.trailing_zeros() as usize;
                        let fx = w * 64 + b;
                        let cx = fx / f;
                        coarse_row[cx] = true;
                        any = true;
                        // Skip the rest of this coarse cell's bits in the word.
                        let next = ((cx + 1) * f).saturating_sub(w * 64);
                        bits = if next >= 64 {
                            0
                        } else {
                            bits & (u64::MAX << next)
                        };
                    }
                }
            }
            if any {
                for (cx, _) in coarse_row.iter().enumerate().filter(|(_, b)| **b) {
                    out.set((cx as u32, cy), true);
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
