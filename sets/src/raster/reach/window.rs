//! A [`ReachSet`] that stores its reach over a window of cells: a target's set around its box,
//! with the far field of its box outside; an undetected set around its UAV, with a summary of
//! lower bounds per block outside (the module docs of [`super`] say why both keep the
//! guarantee).

use super::summary::{BLOCK, Summary};
use super::{GAPS, REACH_UNIT_M, ReachSet, Scan, gap_cells, reached_units};
use crate::grid::GroundGrid;
use crate::math::Real;
use crate::raster::{CellBox, CellSet, WordBound};

/// What a set knows of the reach of the cells it does not store.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Far {
    /// Nothing: the set stores every cell.
    Nothing,
    /// A target's set: the bound of its box ([`FarField`]), and no cell of the set outside
    /// the window.
    OfBox(FarField),
    /// An undetected set kept over a window ([`ReachSet::keep_window`]): a lower bound per
    /// block, and cells of the set anywhere.
    Summary(Box<Summary>),
}

impl Far {
    /// Whether the set may hold cells outside its window.
    pub(super) fn holds_outside(&self) -> bool {
        matches!(self, Far::Summary(_))
    }
}

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

    /// No row and no word.
    pub(super) fn nothing() -> Self {
        Self {
            rows: (0, 0),
            words: (0, 0),
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

    /// The part rounded out to whole blocks of rows (the words are whole blocks already); the
    /// caller clamps the rows to the grid.
    fn whole_blocks(self) -> Self {
        Self {
            rows: (
                self.rows.0 / BLOCK * BLOCK,
                self.rows.1.div_ceil(BLOCK).saturating_mul(BLOCK),
            ),
            words: self.words,
        }
    }

    /// Whether every cell of block `(bx, by)` of a grid `ny` rows high is stored.
    fn holds_block(&self, bx: u32, by: u32, ny: u32) -> bool {
        let (y0, y1) = (by * BLOCK, ((by + 1) * BLOCK).min(ny));
        self.word_range()
            .contains(&(bx as usize * BLOCK as usize / 64))
            && self.rows.0 <= y0
            && y1 <= self.rows.1
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
            far: Far::OfBox(FarField::new(grid, bbox, self.clock_m)),
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
        match &self.far {
            Far::Nothing => span.fill(0),
            Far::OfBox(far) => {
                span.fill(0);
                far.raise_span(iy, x0, span);
            }
            Far::Summary(summary) => summary.fill_span(iy, x0, span),
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
            match &self.far {
                Far::Nothing => 0,
                Far::OfBox(far) => far.tau(ix, iy),
                Far::Summary(summary) => summary.tau_of_cell(ix, iy),
            }
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
            self.far = Far::OfBox(far);
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
        let Far::OfBox(far) = self.far else {
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

    /// Widens the window to hold `part` (clamped to the grid; for a set kept over a window
    /// around its UAV, rounded out to whole blocks); the new cells take the far field. A set
    /// without a far field stores every cell already.
    pub(super) fn store(&mut self, part: Stored) {
        let part = match self.far {
            Far::Nothing => return,
            Far::OfBox(_) => part,
            Far::Summary(_) => part.whole_blocks(),
        };
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
    /// take), and the cells outside `part` are forgotten (a target's set has no cell there; an
    /// undetected set folds their reach into its summary first).
    fn reshape(&mut self, part: Stored) {
        if part == self.stored {
            return;
        }
        debug_assert!(
            self.far.holds_outside()
                || self.rows.0 >= self.rows.1
                || (part.rows.0 <= self.rows.0 && self.rows.1 <= part.rows.1),
            "the set's rows {:?} outside {:?}",
            self.rows,
            part.rows
        );
        self.fold_leaving(&part);
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

/// The cells an advance adds outside the window, `(row, word, bits)`, and each block it
/// visited with whether it took all of its cells ([`ReachSet::outside_growth`]).
#[derive(Debug, Default)]
pub(super) struct OutsideGrowth {
    cells: Vec<(u32, usize, u64)>,
    settled: Vec<(u32, u32, bool)>,
}

/// An undetected set kept over a window around its UAV (the module docs of [`super`], "A
/// window around the UAV").
impl ReachSet {
    /// The set keeps its reach over a window ([`ReachSet::set_window`]) and, outside it, a
    /// lower bound per block of [`BLOCK`] x [`BLOCK`] cells; it may hold cells anywhere. Until
    /// the first [`ReachSet::set_window`] every cell stays stored, so the set is unchanged.
    #[must_use]
    pub fn keep_window(mut self) -> Self {
        if matches!(self.far, Far::Nothing) && self.margin.is_none() {
            self.far = Far::Summary(Box::new(Summary::new(self.cells.nx(), self.cells.ny())));
        }
        self
    }

    /// Whether the set is kept over a window ([`ReachSet::keep_window`]).
    pub fn keeps_window(&self) -> bool {
        self.far.holds_outside()
    }

    /// Stores the reach over `window` (rounded out to whole words of columns and blocks of
    /// rows, clamped to the grid) and nowhere else: the cells leaving it fold their reach into
    /// their block's bound, and the cells entering it take their block's bound. Only a set
    /// kept over a window moves it; for any other set this does nothing.
    pub fn set_window(&mut self, window: &CellBox) {
        if !self.far.holds_outside() || self.cells.nx() == 0 || self.cells.ny() == 0 {
            return;
        }
        let part = Stored::of_box(&CellBox {
            x0: window.x0.min(self.cells.nx() - 1),
            y0: window.y0.min(self.cells.ny() - 1),
            x1: window.x1.min(self.cells.nx() - 1),
            y1: window.y1.min(self.cells.ny() - 1),
        })
        .whole_blocks();
        let part = Stored {
            rows: (part.rows.0, part.rows.1.min(self.cells.ny())),
            words: part.words,
        };
        self.reshape(part);
    }

    /// The blocks of the stored part that `part` does not hold give their cells' least reach
    /// to their bound ([`Summary::fold`]); nothing for a set without a summary.
    pub(super) fn fold_leaving(&mut self, part: &Stored) {
        let Far::Summary(summary) = &self.far else {
            return;
        };
        let ny = self.cells.ny();
        let (nbx, nby) = summary.blocks();
        let mut folds = Vec::new();
        for by in self.stored.rows.0 / BLOCK..self.stored.rows.1.div_ceil(BLOCK).min(nby) {
            for bx in 0..nbx {
                if !self.stored.holds_block(bx, by, ny) || part.holds_block(bx, by, ny) {
                    continue;
                }
                folds.push((bx, by, self.least_reach_of_block(bx, by)));
            }
        }
        if let Far::Summary(summary) = &mut self.far {
            for (bx, by, least) in folds {
                summary.fold(bx, by, least);
            }
        }
    }

    /// The least stored reach of the cells of block `(bx, by)`, which the window holds.
    fn least_reach_of_block(&self, bx: u32, by: u32) -> u32 {
        let (x0, x1) = (bx * BLOCK, ((bx + 1) * BLOCK).min(self.cells.nx()));
        let (y0, y1) = (by * BLOCK, ((by + 1) * BLOCK).min(self.cells.ny()));
        (y0..y1)
            .map(|iy| {
                let at = self.index(x0, iy);
                self.reach[at..at + (x1 - x0) as usize]
                    .iter()
                    .copied()
                    .min()
                    .unwrap_or(u32::MAX)
            })
            .min()
            .unwrap_or(u32::MAX)
    }

    /// The cells of block `(bx, by)` in row `iy` as bits of word `w = bx * BLOCK / 64`.
    fn block_bits(&self, bx: u32) -> (usize, u64) {
        let x0 = bx * BLOCK;
        let width = BLOCK.min(self.cells.nx() - x0);
        let mask = if width == 64 {
            u64::MAX
        } else {
            (1u64 << width) - 1
        };
        ((x0 / 64) as usize, mask << (x0 % 64))
    }

    /// The advance outside the window, read from the cells before it: every unsettled block
    /// whose bound the clock `reached` (reach units) has come to gives the set its cells, those
    /// `bound` allows (`None`: all); a block that `bound` cut stays unsettled, so the next
    /// advance looks at it again. [`ReachSet::grow_outside`] applies it.
    pub(super) fn outside_growth(
        &self,
        reached: u32,
        mut bound: Option<&mut dyn WordBound>,
    ) -> OutsideGrowth {
        let mut growth = OutsideGrowth::default();
        let Far::Summary(summary) = &self.far else {
            return growth;
        };
        let (stored, ny) = (self.stored, self.cells.ny());
        for (bx, by) in summary.due(reached, |bx, by| stored.holds_block(bx, by, ny)) {
            let (w, bits) = self.block_bits(bx);
            let mut whole = true;
            for iy in by * BLOCK..((by + 1) * BLOCK).min(ny) {
                let fresh = bits & !self.cells.row(iy)[w];
                if fresh == 0 {
                    continue;
                }
                let keep = match bound.as_deref_mut() {
                    Some(b) if !b.may_hold_row(iy) || !b.may_hold(iy, w) => 0,
                    Some(b) => fresh & b.word(&self.cells, iy, w),
                    None => fresh,
                };
                whole &= keep == fresh;
                if keep != 0 {
                    growth.cells.push((iy, w, keep));
                }
            }
            growth.settled.push((bx, by, whole));
        }
        growth
    }

    /// Applies [`ReachSet::outside_growth`].
    pub(super) fn grow_outside(&mut self, growth: OutsideGrowth) {
        for (iy, w, keep) in growth.cells {
            self.cells.row_mut(iy)[w] |= keep;
            self.hold_row(iy);
        }
        if let Far::Summary(summary) = &mut self.far {
            for (bx, by, whole) in growth.settled {
                summary.settle(bx, by, whole);
            }
        }
    }

    /// Marks unsettled the blocks outside the window that hold bits of `gone`, cells just
    /// removed from word `w` of row `iy`.
    pub(super) fn unsettle_removed(&mut self, iy: u32, w: usize, gone: u64) {
        if gone == 0 || self.stored.holds(iy, w) {
            return;
        }
        if let Far::Summary(summary) = &mut self.far {
            for byte in 0..8u32 {
                if gone >> (8 * byte) & 0xFF != 0 {
                    summary.unsettle(w as u32 * 64 / BLOCK + byte, iy / BLOCK);
                }
            }
        }
    }

    /// Raises the bounds of the blocks outside the window from ground `free` proven free at
    /// the clock `clock_m` over `window` ([`Summary::raise_free`]), and, when that clock is
    /// behind the set's, removes the cells of the raised blocks whose bound the clock has not
    /// reached: by (I1) none holds a target now. Nothing for a set without a summary, or when
    /// `window` lies inside the stored cells (the exact correction raised all of it).
    pub(super) fn raise_summary(
        &mut self,
        grid: &GroundGrid,
        free: &CellSet,
        window: &CellBox,
        clock_m: Real,
    ) {
        let Far::Summary(summary) = &mut self.far else {
            return;
        };
        let (nx, ny) = (self.cells.nx(), self.cells.ny());
        if nx == 0 || ny == 0 || window.x0 > window.x1 || window.y0 > window.y1 {
            return;
        }
        let (x1, y1) = (window.x1.min(nx - 1), window.y1.min(ny - 1));
        let (nbx, nby) = summary.blocks();
        let blocks = CellBox {
            x0: (window.x0 / BLOCK).saturating_sub(1),
            y0: (window.y0 / BLOCK).saturating_sub(1),
            x1: (x1 / BLOCK + 1).min(nbx - 1),
            y1: (y1 / BLOCK + 1).min(nby - 1),
        };
        let stored = self.stored;
        if (blocks.y0..=blocks.y1)
            .all(|by| (blocks.x0..=blocks.x1).all(|bx| stored.holds_block(bx, by, ny)))
        {
            return;
        }
        // A block is free when it lies in the window and every one of its cells is free.
        let free_block = |bx: u32, by: u32| {
            let (cx0, cx1) = (bx * BLOCK, ((bx + 1) * BLOCK).min(nx) - 1);
            let (cy0, cy1) = (by * BLOCK, ((by + 1) * BLOCK).min(ny) - 1);
            if cx0 < window.x0 || cx1 > x1 || cy0 < window.y0 || cy1 > y1 {
                return false;
            }
            let width = cx1 - cx0 + 1;
            let mask = if width == 64 {
                u64::MAX
            } else {
                (1u64 << width) - 1
            } << (cx0 % 64);
            (cy0..=cy1).all(|iy| free.row(iy)[(cx0 / 64) as usize] & mask == mask)
        };
        let raised = GAPS.with_borrow_mut(|gaps| {
            summary.raise_free(
                grid,
                &blocks,
                clock_m,
                free_block,
                |bx, by| stored.holds_block(bx, by, ny),
                gaps,
            )
        });
        if clock_m >= self.clock_m {
            return;
        }
        let reached = reached_units(self.clock_m);
        let gone: Vec<(u32, u32)> = raised
            .into_iter()
            .filter(|&(bx, by)| summary.tau(bx, by) > reached)
            .collect();
        for &(bx, by) in &gone {
            summary.unsettle(bx, by);
        }
        for (bx, by) in gone {
            let (w, bits) = self.block_bits(bx);
            for iy in by * BLOCK..((by + 1) * BLOCK).min(ny) {
                if self.cells.row(iy)[w] & bits != 0 {
                    self.cells.row_mut(iy)[w] &= !bits;
                }
            }
        }
    }
}
