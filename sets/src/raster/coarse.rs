//! "Any cell" coarsening: the cells of an area cut into blocks of `factor x factor` fine
//! cells, a block in the coarse set when any of its fine cells is in the fine set. A
//! coarsened set is outer: it never looks smaller than the set it comes from. The planner
//! plans on such cells (`uav_agent::guidance::CoarseGrid`), and the viewer sends the large
//! layers so.

use super::{CellBox, CellSet};
use crate::grid::GroundGrid;

impl CellSet {
    /// The blocks of `area` that hold a cell of `self`, as a set on `coarse`: block
    /// `(cx, cy)` covers the fine cells `area.x0 + cx * factor ..` and
    /// `area.y0 + cy * factor ..`, `factor` of each (the blocks at the far edges of `area`
    /// are partial). `coarse` must have one cell per block: `ceil(w / factor)` columns and
    /// `ceil(h / factor)` rows for an area of `w x h` cells.
    ///
    /// The fine rows of a block row are merged a word at a time first, so each block is
    /// looked at once per block row.
    pub fn coarsen_any(&self, area: &CellBox, factor: u32, coarse: &GroundGrid) -> CellSet {
        let factor = factor.max(1);
        debug_assert_eq!(coarse.nx, (area.x1 - area.x0 + 1).div_ceil(factor));
        debug_assert_eq!(coarse.ny, (area.y1 - area.y0 + 1).div_ceil(factor));
        let mut out = CellSet::empty(coarse);
        let f = factor as usize;
        let (x0, x1) = (area.x0 as usize, area.x1 as usize);
        let (w0, w1) = (x0 / 64, x1 / 64);
        let mut merged = vec![0u64; w1 - w0 + 1];
        for cy in 0..coarse.ny {
            let y0 = area.y0 + cy * factor;
            let y1 = (y0 + factor - 1).min(area.y1);
            merged.fill(0);
            for fy in y0..=y1 {
                for (m, &word) in merged.iter_mut().zip(&self.row(fy)[w0..=w1]) {
                    *m |= word;
                }
            }
            // Only the columns of the area count.
            merged[0] &= u64::MAX << (x0 % 64);
            if let Some(last) = merged.last_mut() {
                *last &= u64::MAX >> (63 - x1 % 64);
            }
            for (i, &word) in merged.iter().enumerate() {
                let w = (w0 + i) * 64;
                let mut bits = word;
                while bits != 0 {
                    let x = w + bits.trailing_zeros() as usize;
                    let cx = (x - x0) / f;
                    out.set((cx as u32, cy), true);
                    // Skip the rest of this block's bits in the word.
                    let next = (x0 + (cx + 1) * f).saturating_sub(w);
                    bits = if next >= 64 {
                        0
                    } else {
                        bits & (u64::MAX << next)
                    };
                }
            }
        }
        out
    }
}
