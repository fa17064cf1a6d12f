//! A [`ReachSet`] that stores its reach over a window of cells around its box, with the far
//! field of its box outside (the module docs of [`super`] say why this keeps the guarantee).

use super::{REACH_UNIT_M, ReachSet, Scan, gap_cells};
use crate::grid::GroundGrid;
use crate::math::Real;
use crate::raster::{CellBox, CellSet};

/// Rows a window widens by at least when the clock comes near its edge, so that a growing
/// set widens it every few steps rather than at every step.
const WIDEN_ROWS: u32 = 32;

/// Words (of 64 columns) a window widens by at least when the clock comes near its side.
const WIDEN_WORDS: usize = 1;

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

    /// Raises every reach of `span`, the cells `x0..` of row `iy`, to the bound.
    pub(super) fn raise_span(&self, iy: u32, x0: u32, span: &mut [u32]) {
        let b = &self.bbox;
        let gy = gap_cells(iy, b.y0, b.y1);
        let gy2 = (gy * gy) as f32;
        for (ix, tau) in (x0..).zip(span.iter_mut()) {
            let gx = gap_cells(ix, b.x0, b.x1) as f32;
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

    /// The least bound over column `ix` (a row of the box has no vertical gap).
    fn column_least(&self, ix: u32) -> u32 {
        self.tau(ix, self.bbox.y0)
    }

    /// The bound at a squared gap of `gap2` cells². f32 keeps the row loop vectorised; its
    /// rounding (below 1e-6 relative) and the float to integer truncation are covered by
    /// taking two units off. Every step is monotone in `gap2`, so cells farther from the box
    /// never have a smaller bound.
    fn units(&self, gap2: f32) -> u32 {
        let units = gap2.sqrt() * self.unit + self.clock;
        (units * (1.0 - 1e-6) - 2.0).clamp(0.0, (u32::MAX - 1) as f32) as u32
    }
}

/// The part of the grid whose reach a set stores: rows `rows.0..rows.1` and the words (of 64
/// columns) `words.0..words.1` of each.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Stored {
    pub(super) rows: (u32, u32),
    pub(super) words: (usize, usize),
}

impl Stored {
    /// Every row and word of a grid of `cells`' shape.
    pub(super) fn everything(cells: &CellSet) -> Self {
        Self {
            rows: (0, cells.ny()),
            words: (0, cells.words_per_row()),
        }
    }

    /// The rows of `b` and the words holding its columns.
    pub(super) fn of_box(b: &CellBox) -> Self {
        Self {
            rows: (b.y0, b.y1 + 1),
            words: (b.x0 as usize / 64, b.x1 as usize / 64 + 1),
        }
    }

    /// The columns of the stored words in a grid `nx` cells wide (the last word cut there).
    pub(super) fn columns(&self, nx: u32) -> std::ops::Range<u32> {
        let x = |w: usize| (w as u32).saturating_mul(64).min(nx);
        x(self.words.0)..x(self.words.1)
    }

    /// The stored words of each stored row.
    pub(super) fn word_range(&self) -> std::ops::Range<usize> {
        self.words.0..self.words.1
    }

    /// Whether word `w` of row `iy` is stored.
    fn holds(&self, iy: u32, w: usize) -> bool {
        (self.rows.0..self.rows.1).contains(&iy) && self.word_range().contains(&w)
    }

    /// Whether no cell is stored.
    fn is_empty(&self) -> bool {
        self.rows.0 >= self.rows.1 || self.words.0 >= self.words.1
    }

    /// The smallest part holding both.
    fn union(&self, other: &Self) -> Self {
        if self.is_empty() {
            return *other;
        }
        if other.is_empty() {
            return *self;
        }
        Self {
            rows: (self.rows.0.min(other.rows.0), self.rows.1.max(other.rows.1)),
            words: (
                self.words.0.min(other.words.0),
                self.words.1.max(other.words.1),
            ),
        }
    }
}

impl ReachSet {
    /// The set keeps its reach over the cells within `margin` cells of its box only (rows,
    /// and columns rounded out to whole words of 64), from the next [`ReachSet::bound_by_box`]
    /// on (which cuts the window); outside them the reach is the bound of the set's box at that
    /// clock. For a target's set, whose cells are a small part of the grid: its storage, its
    /// copies and its bounds then cost its box, not the grid's rows.
    #[must_use]
    pub fn with_margin(mut self, margin: u32) -> Self {
        self.margin = Some(margin);
        self
    }

    /// The rows whose reach the set stores (every row, unless it has a margin).
    pub fn stored_rows(&self) -> std::ops::Range<u32> {
        self.stored.rows.0..self.stored.rows.1
    }

    /// The columns whose reach the set stores in each stored row (every column, unless it has
    /// a margin): whole words of 64 columns, the last one cut at the grid's edge.
    pub fn stored_columns(&self) -> std::ops::Range<u32> {
        self.stored.columns(self.cells.nx())
    }

    /// The stored words that hold columns of `window`.
    pub(super) fn stored_words_of(&self, window: &CellBox) -> std::ops::Range<usize> {
        (window.x0 as usize / 64).max(self.stored.words.0)
            ..(window.x1 as usize / 64 + 1).min(self.stored.words.1)
    }

    /// Whether the reach of cell `(ix, iy)` is stored.
    pub(super) fn stores(&self, ix: u32, iy: u32) -> bool {
        self.stored_rows().contains(&iy) && self.stored_columns().contains(&ix)
    }

    /// Cells per stored row.
    pub(super) fn stride(&self) -> usize {
        self.stored_columns().len()
    }

    /// Words per stored row.
    pub(super) fn stored_words(&self) -> usize {
        self.stored.word_range().len()
    }

    /// This set met with `outer`, an outer raster of the targets the copy is for at the set's
    /// clock (a measurement of one target, or a peer's set of it, grown to this clock), with
    /// its reach raised to the bound of its box ([`ReachSet::bound_by_box`]) and kept over the
    /// cells within `margin` of its cells: the cells, and the reach over those cells, of
    /// cloning the set, meeting `outer` and bounding by the box; the reach of the other cells
    /// is that bound alone. It costs the window, not the grid.
    pub fn restricted_copy(&self, grid: &GroundGrid, outer: &CellSet, margin: u32) -> Self {
        debug_assert!(self.cells.same_shape(outer));
        let Some(bbox) = outer.bounding_box() else {
            // No cell: the copy is empty wherever it is stored.
            let mut copy = self.clone().with_margin(margin);
            copy.intersect(outer);
            return copy;
        };
        let part = self.margin_box(&bbox, margin);
        let (lo, hi) = part.rows;
        let mut cells = CellSet::empty(grid);
        for iy in lo..hi {
            let (mine, theirs) = (self.cells.row(iy), outer.row(iy));
            if theirs.iter().all(|&w| w == 0) {
                continue;
            }
            for ((dst, &m), &t) in cells.row_mut(iy).iter_mut().zip(mine).zip(theirs) {
                *dst = m & t;
            }
        }
        let mut copy = Self {
            pending: Vec::new(),
            scanned: Vec::new(),
            rows: cells
                .row_range_within(lo..hi)
                .map_or((0, 0), |(first, last)| (first, last + 1)),
            cells,
            reach: Vec::new(),
            stored: part,
            far: Some(FarField::new(grid, bbox, self.clock_m)),
            margin: Some(margin),
            clock_m: self.clock_m,
        };
        let (x0, stride) = (copy.stored_columns().start, copy.stride());
        copy.reach = vec![0; (hi - lo) as usize * stride];
        if stride > 0 {
            for (iy, span) in (lo..hi).zip(copy.reach.chunks_exact_mut(stride)) {
                self.copy_reach_span(iy, x0, span);
            }
        }
        let words = (hi - lo) as usize * copy.stored_words();
        copy.pending = vec![u32::MAX; words];
        copy.scanned = vec![Scan::default(); words];
        copy.rebuild_pending();
        copy.bound_by_box(grid);
        copy
    }

    /// The cells of `bbox` grown by `margin` on each side, clamped to the grid, with the
    /// columns rounded out to whole words.
    fn margin_box(&self, bbox: &CellBox, margin: u32) -> Stored {
        let (nx, ny) = (self.cells.nx(), self.cells.ny());
        Stored {
            rows: (
                bbox.y0.saturating_sub(margin),
                bbox.y1.saturating_add(1).saturating_add(margin).min(ny),
            ),
            words: (
                bbox.x0.saturating_sub(margin) as usize / 64,
                (bbox.x1.saturating_add(margin).min(nx.saturating_sub(1)) as usize / 64 + 1)
                    .min(self.cells.words_per_row()),
            ),
        }
    }

    /// Writes the reach of cells `x0..x0 + span.len()` of row `iy` into `span`: the stored
    /// one where it is stored, else the far field.
    pub(super) fn copy_reach_span(&self, iy: u32, x0: u32, span: &mut [u32]) {
        span.fill(0);
        if let Some(far) = &self.far {
            far.raise_span(iy, x0, span);
        }
        if !self.stored_rows().contains(&iy) {
            return;
        }
        let columns = self.stored_columns();
        let (from, to) = (
            columns.start.max(x0),
            columns.end.min(x0.saturating_add(span.len() as u32)),
        );
        if from < to {
            let src = self.index(from, iy);
            span[(from - x0) as usize..(to - x0) as usize]
                .copy_from_slice(&self.reach[src..src + (to - from) as usize]);
        }
    }

    /// The reach of cell `(ix, iy)` of the grid.
    pub(super) fn reach_at(&self, ix: u32, iy: u32) -> u32 {
        if self.stores(ix, iy) {
            self.reach[self.index(ix, iy)]
        } else {
            self.far.as_ref().map_or(0, |far| far.tau(ix, iy))
        }
    }

    /// The bound of the set's box, [`ReachSet::bound_by_box`]'s work: with a margin, the
    /// window is first cut to the cells within the margin of the box, and the bound becomes
    /// the far field.
    pub(super) fn bound_by(&mut self, far: FarField, bbox: &CellBox) {
        // The box is the set's: its rows are exactly the rows holding cells.
        self.rows = (bbox.y0, bbox.y1 + 1);
        if let Some(margin) = self.margin {
            let part = self.margin_box(bbox, margin);
            self.reshape(part);
            self.far = Some(far);
        }
        self.scanned.fill(Scan::default());
        let (x0, stride) = (self.stored_columns().start, self.stride());
        if stride == 0 {
            return;
        }
        for (iy, span) in self.stored_rows().zip(self.reach.chunks_exact_mut(stride)) {
            far.raise_span(iy, x0, span);
        }
    }

    /// Widens the window before an advance to the clock `reached` (reach units) so that every
    /// cell the clock reaches is stored: the far field grows with the gap to its box, so once
    /// the rows and the columns next to the window are out of reach, so is every cell beyond.
    pub(super) fn widen_for(&mut self, reached: u32) {
        let Some(far) = self.far else {
            return;
        };
        let (ny, wpr) = (self.cells.ny(), self.cells.words_per_row());
        let Stored {
            rows: (mut lo, mut hi),
            words: (mut w0, mut w1),
        } = self.stored;
        while lo > 0 && far.row_least(lo - 1) <= reached {
            lo = lo.saturating_sub(WIDEN_ROWS);
        }
        while hi < ny && far.row_least(hi) <= reached {
            hi = hi.saturating_add(WIDEN_ROWS).min(ny);
        }
        while w0 > 0 && far.column_least((w0 * 64 - 1) as u32) <= reached {
            w0 = w0.saturating_sub(WIDEN_WORDS);
        }
        while w1 < wpr && far.column_least((w1 * 64) as u32) <= reached {
            w1 = (w1 + WIDEN_WORDS).min(wpr);
        }
        self.store(Stored {
            rows: (lo, hi),
            words: (w0, w1),
        });
    }

    /// Widens the window to hold `part` (clamped to the grid); the new cells take the far
    /// field. A set without a far field stores every cell already.
    pub(super) fn store(&mut self, part: Stored) {
        if self.far.is_none() {
            return;
        }
        let part = Stored {
            rows: (part.rows.0, part.rows.1.min(self.cells.ny())),
            words: (part.words.0, part.words.1.min(self.cells.words_per_row())),
        };
        let wanted = self.stored.union(&part);
        if wanted != self.stored {
            self.reshape(wanted);
        }
    }

    /// Stores the reach over `part` exactly: the cells stored before keep their reach, the
    /// others take the far field (a set without one stores every cell, so it has none to
    /// take), and the cells outside `part` are forgotten (the set must have no cell there).
    fn reshape(&mut self, part: Stored) {
        if part == self.stored {
            return;
        }
        debug_assert!(
            self.rows.0 >= self.rows.1
                || (part.rows.0 <= self.rows.0 && self.rows.1 <= part.rows.1),
            "the set's rows {:?} outside {:?}",
            self.rows,
            part.rows
        );
        let columns = part.columns(self.cells.nx());
        let (x0, stride) = (columns.start, columns.len());
        let words = part.words.1.saturating_sub(part.words.0);
        let rows = part.rows.1.saturating_sub(part.rows.0) as usize;
        let mut reach = vec![0u32; rows * stride];
        let mut pending = vec![u32::MAX; rows * words];
        let mut scanned = vec![Scan::default(); rows * words];
        if stride > 0 && words > 0 {
            for (iy, (span, (pend, scan))) in (part.rows.0..part.rows.1).zip(
                reach.chunks_exact_mut(stride).zip(
                    pending
                        .chunks_exact_mut(words)
                        .zip(scanned.chunks_exact_mut(words)),
                ),
            ) {
                self.copy_reach_span(iy, x0, span);
                for (k, w) in (part.words.0..part.words.1).enumerate() {
                    if self.stored.holds(iy, w) {
                        let slot = self.slot(iy, w);
                        (pend[k], scan[k]) = (self.pending[slot], self.scanned[slot]);
                    } else {
                        // The set has no cell outside its window: every cell counts.
                        let from = w * 64 - x0 as usize;
                        let to = (from + 64).min(stride);
                        pend[k] = span[from..to].iter().copied().min().unwrap_or(u32::MAX);
                    }
                }
            }
        }
        self.reach = reach;
        self.pending = pending;
        self.scanned = scanned;
        self.stored = part;
    }
}
