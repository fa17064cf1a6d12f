//! Helpers shared by the raster proptests.

use proptest::prelude::*;
use sets::grid::GroundGrid;
use sets::raster::{CellBox, CellSet};

/// A box of cells inside an `n x n` grid, sides from 1 to `max_side` cells (clipped).
pub fn cell_box(n: u32, max_side: u32) -> impl Strategy<Value = CellBox> {
    (0..n, 0..n, 1..=max_side, 1..=max_side).prop_map(move |(x0, y0, w, h)| CellBox {
        x0,
        y0,
        x1: (x0 + w - 1).min(n - 1),
        y1: (y0 + h - 1).min(n - 1),
    })
}

/// The cells of a box as a set.
pub fn box_set(g: &GroundGrid, b: &CellBox) -> CellSet {
    let mut s = CellSet::empty(g);
    for iy in b.y0..=b.y1 {
        s.fill_row_span(iy, b.x0, b.x1);
    }
    s
}
