//! A [`ReachSet`] that stores its reach over a window of rows, with the far field of its box
//! outside (the module docs of [`super`] say why this keeps the guarantee).

use super::{REACH_UNIT_M, ReachSet, Scan, gap_cells};
use crate::grid::GroundGrid;
use crate::math::Real;
use crate::raster::{CellBox, CellSet};

/// Rows a window widens by at least when the clock comes near its edge, so that a growing
/// set widens it every few steps rather than at every step.
const WIDEN_ROWS: u32 = 32;

/// The reach implied outside a set's window: when the clock was `clock`, every target lay in
/// the closed rectangle of `bbox`, so a cell's square is at least its gap to that rectangle
/// away from them, and `τ(c) = gap · unit + clock` keeps (I1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct FarField {
    bbox: CellBox,
    /// Reach units per cell side.
    unit: f32,
    /// The clock of the bound, reach units.
    clock: f32,
}

impl FarField {
    /// The bound of `bbox` (which holds every target) at the clock `clock_m`.
    pub(super) fn new(grid: &GroundGrid, bbox: CellBox, clock_m: Real) -> Self {
        Self {
            bbox,
            unit: (grid.cell_m / REACH_UNIT_M) as f32,
            clock: (clock_m / REACH_UNIT_M) as f32,
        }
    }

    /// Raises every reach of `row`, the whole row `iy` of the grid, to the bound.
    pub(super) fn raise_row(&self, iy: u32, row: &mut [u32]) {
        let b = &self.bbox;
        let gy = gap_cells(iy, b.y0, b.y1);
        let gy2 = (gy * gy) as f32;
        for (ix, tau) in row.iter_mut().enumerate() {
            let gx = gap_cells(ix as u32, b.x0, b.x1) as f32;
            *tau = (*tau).max(self.units(gx * gx + gy2));
        }
    }

    /// The bound of cell `(ix, iy)`.
    pub(super) fn tau(&self, ix: u32, iy: u32) -> u32 {
        let b = &self.bbox;
        let gx = gap_cells(ix, b.x0, b.x1) as f32;
        let gy = gap_cells(iy, b.y0, b.y1);
        self.units(gx * gx + (gy * gy) as f32)
    }

    /// The least bound over row `iy` (a column of the box has no horizontal gap).
    fn row_least(&self, iy: u32) -> u32 {
        self.tau(self.bbox.x0, iy)
    }

    /// The bound at a squared gap of `gap2` cells². f32 keeps the row loop vectorised; its
    /// rounding (below 1e-6 relative) and the float to integer truncation are covered by
    /// taking two units off. Every step is monotone in `gap2`, so rows farther from the box
    /// never have a smaller bound.
    fn units(&self, gap2: f32) -> u32 {
        let units = gap2.sqrt() * self.unit + self.clock;
        (units * (1.0 - 1e-6) - 2.0).clamp(0.0, (u32::MAX - 1) as f32) as u32
    }
}

impl ReachSet {
    /// The set keeps its reach over the rows within `margin_rows` of its cells only, from the
    /// next [`ReachSet::bound_by_box`] on (which cuts the window); outside them the reach is
    /// the bound of the set's box at that clock. For a target's set, whose cells are a small
    /// part of the grid: its storage, its copies and its bounds then cost its rows.
    #[must_use]
    pub fn with_row_margin(mut self, margin_rows: u32) -> Self {
        self.row_margin = Some(margin_rows);
        self
    }

    /// The rows whose reach the set stores (every row, unless it has a row margin).
    pub fn stored_rows(&self) -> std::ops::Range<u32> {
        self.stored.0..self.stored.1
    }

    /// This set met with `outer`, an outer raster of the targets the copy is for at the set's
    /// clock (a measurement of one target, or a peer's set of it, grown to this clock), with
    /// its reach raised to the bound of its box ([`ReachSet::bound_by_box`]) and kept over the
    /// rows within `margin_rows` of its cells: the cells, and the reach over those rows, of
    /// cloning the set, meeting `outer` and bounding by the box; the reach of the other rows
    /// is that bound alone. It costs the window's rows, not the grid's.
    pub fn restricted_copy(&self, grid: &GroundGrid, outer: &CellSet, margin_rows: u32) -> Self {
        debug_assert!(self.cells.same_shape(outer));
        let Some(bbox) = outer.bounding_box() else {
            // No cell: the copy is empty wherever it is stored.
            let mut copy = self.clone().with_row_margin(margin_rows);
            copy.intersect(outer);
            return copy;
        };
        let (lo, hi) = self.margin_rows(&bbox, margin_rows);
        let mut cells = CellSet::empty(grid);
        for iy in lo..hi {
            for ((dst, &mine), &theirs) in cells
                .row_mut(iy)
                .iter_mut()
                .zip(self.cells.row(iy))
                .zip(outer.row(iy))
            {
                *dst = mine & theirs;
            }
        }
        let nx = self.cells.nx() as usize;
        let mut reach = vec![0; (hi - lo) as usize * nx];
        for (iy, row) in (lo..hi).zip(reach.chunks_exact_mut(nx)) {
            self.copy_reach_row(iy, row);
        }
        let words = (hi - lo) as usize * self.cells.words_per_row();
        let mut copy = Self {
            pending: vec![u32::MAX; words],
            scanned: vec![Scan::default(); words],
            rows: cells
                .row_range_within(lo..hi)
                .map_or((0, 0), |(first, last)| (first, last + 1)),
            cells,
            reach,
            stored: (lo, hi),
            far: Some(FarField::new(grid, bbox, self.clock_m)),
            row_margin: Some(margin_rows),
            clock_m: self.clock_m,
        };
        copy.rebuild_pending();
        copy.bound_by_box(grid);
        copy
    }

    /// The rows of `bbox` grown by `margin` rows on each side, clamped to the grid.
    fn margin_rows(&self, bbox: &CellBox, margin: u32) -> (u32, u32) {
        let ny = self.cells.ny();
        (
            bbox.y0.saturating_sub(margin),
            bbox.y1.saturating_add(1).saturating_add(margin).min(ny),
        )
    }

    /// Writes the reach of row `iy` into `row`: the stored one, else the far field.
    pub(super) fn copy_reach_row(&self, iy: u32, row: &mut [u32]) {
        if self.stored_rows().contains(&iy) {
            let nx = self.cells.nx() as usize;
            let start = (iy - self.stored.0) as usize * nx;
            row.copy_from_slice(&self.reach[start..start + nx]);
        } else {
            row.fill(0);
            if let Some(far) = &self.far {
                far.raise_row(iy, row);
            }
        }
    }

    /// The reach of cell `(ix, iy)` of the grid.
    pub(super) fn reach_at(&self, ix: u32, iy: u32) -> u32 {
        if self.stored_rows().contains(&iy) {
            self.reach[self.index(ix, iy)]
        } else {
            self.far.as_ref().map_or(0, |far| far.tau(ix, iy))
        }
    }

    /// The bound of the set's box, [`ReachSet::bound_by_box`]'s work: with a row margin, the
    /// window is first cut to the rows within the margin of the box, and the bound becomes
    /// the far field.
    pub(super) fn bound_by(&mut self, far: FarField, bbox: &CellBox) {
        // The box is the set's: its rows are exactly the rows holding cells.
        self.rows = (bbox.y0, bbox.y1 + 1);
        if let Some(margin) = self.row_margin {
            let (lo, hi) = self.margin_rows(bbox, margin);
            self.store_rows(lo, hi);
            self.keep_rows(lo, hi);
            self.far = Some(far);
        }
        self.scanned.fill(Scan::default());
        let nx = self.cells.nx() as usize;
        for (iy, row) in self.stored_rows().zip(self.reach.chunks_exact_mut(nx)) {
            far.raise_row(iy, row);
        }
    }

    /// Widens the window before an advance to the clock `reached` (reach units) so that every
    /// cell the clock reaches is stored: the far field grows with the gap to its box, so once
    /// the rows next to the window are out of reach, so is every row beyond.
    pub(super) fn widen_for(&mut self, reached: u32) {
        let Some(far) = self.far else {
            return;
        };
        let ny = self.cells.ny();
        let (mut lo, mut hi) = self.stored;
        while lo > 0 && far.row_least(lo - 1) <= reached {
            lo = lo.saturating_sub(WIDEN_ROWS);
        }
        while hi < ny && far.row_least(hi) <= reached {
            hi = hi.saturating_add(WIDEN_ROWS).min(ny);
        }
        self.store_rows(lo, hi);
    }

    /// Widens the window to hold rows `lo..hi` (clamped to the grid); the new rows take the far
    /// field. A set without a far field stores every row already.
    pub(super) fn store_rows(&mut self, lo: u32, hi: u32) {
        let Some(far) = self.far else {
            return;
        };
        let lo = lo.min(self.stored.0);
        let hi = hi.min(self.cells.ny()).max(self.stored.1);
        if (lo, hi) == self.stored {
            return;
        }
        let (nx, wpr) = (self.cells.nx() as usize, self.cells.words_per_row());
        let far_rows = |rows: std::ops::Range<u32>| {
            let mut reach = vec![0; rows.len() * nx];
            let mut pending = Vec::with_capacity(rows.len() * wpr);
            for (iy, row) in rows.zip(reach.chunks_exact_mut(nx)) {
                far.raise_row(iy, row);
                // The set has no cell outside its window: every cell counts.
                pending.extend(
                    row.chunks(64)
                        .map(|w| w.iter().copied().min().unwrap_or(u32::MAX)),
                );
            }
            (reach, pending)
        };
        let (top, top_pending) = far_rows(lo..self.stored.0);
        let (bottom, bottom_pending) = far_rows(self.stored.1..hi);
        let added_above = top_pending.len();
        self.reach.splice(0..0, top);
        self.reach.extend(bottom);
        self.pending.splice(0..0, top_pending);
        self.pending.extend(bottom_pending);
        self.scanned
            .splice(0..0, std::iter::repeat_n(Scan::default(), added_above));
        self.scanned.resize(self.pending.len(), Scan::default());
        self.stored = (lo, hi);
    }

    /// Forgets the reach of the rows outside `lo..hi`, which the window holds; the set has no
    /// cell there.
    fn keep_rows(&mut self, lo: u32, hi: u32) {
        debug_assert!(self.stored.0 <= lo && hi <= self.stored.1);
        debug_assert!(self.rows.0 >= self.rows.1 || (lo <= self.rows.0 && self.rows.1 <= hi));
        let (nx, wpr) = (self.cells.nx() as usize, self.cells.words_per_row());
        let (skip, keep) = ((lo - self.stored.0) as usize, (hi - lo) as usize);
        self.reach.drain(..skip * nx);
        self.reach.truncate(keep * nx);
        self.pending.drain(..skip * wpr);
        self.pending.truncate(keep * wpr);
        self.scanned.drain(..skip * wpr);
        self.scanned.truncate(keep * wpr);
        if self.reach.capacity() > 2 * self.reach.len() {
            self.reach.shrink_to_fit();
            self.pending.shrink_to_fit();
            self.scanned.shrink_to_fit();
        }
        self.stored = (lo, hi);
    }
}
