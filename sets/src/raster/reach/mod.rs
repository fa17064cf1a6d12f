//! Outer sets that carry their sub-cell growth: a [`ReachSet`] is a [`CellSet`] plus, for
//! every cell, a lower bound of how far the set's targets still are from it.
//!
//! # Why
//! Dilating a bit raster by `R = v_max T` at every step rounds the growth out to whole cells,
//! so with 0.5 m cells and `R = 1 m` a set left unobserved grows 1.5 m per step. A
//! [`ReachSet`] grows by `R` per step, exactly, however many steps pass: `n` steps without
//! observation grow it by `n R` plus one cell diagonal (the rasterisation).
//!
//! # What is stored
//! Time enters through a *motion clock* `b = v_max t` in metres: how far any target can have
//! travelled since time 0. Each cell `c` holds a *reach* `τ(c)`, an integer in units of
//! [`REACH_UNIT_M`], and the invariants are, for every target `p(t)` the set must hold:
//!
//! - **(I1)** `dist(p(t), square(c)) ≥ τ(c) · REACH_UNIT_M − b(t)` for every cell;
//! - **(I2)** a cell outside the set's cells has `p(t)` outside its closed square.
//!
//! (I1) is invariant in time: the target moves at most `b(t') − b(t)` between `t` and `t'`,
//! so the distance shrinks at most as fast as the right-hand side. That is why prediction
//! stores nothing: [`ReachSet::advance`] only re-reads which cells the clock reached, the
//! cells with `τ(c) · unit ≤ b`, and any other cell is at a positive distance by (I1).
//!
//! The corrections raise `τ`. When the target is known to lie in an outer raster `M` (every
//! cell whose closed square holds it is in `M`; ground proven free is the complement of an
//! outer raster), a cell outside `M` is at least the gap between its square and the nearest
//! square of `M` away from it ([`super::distance`], exact in integer arithmetic), so
//! `τ(c) ← max(τ(c), ⌊(gap + b) / unit⌋)` keeps (I1), and removing the cell keeps (I2). The
//! floor and a `1e-6`-unit margin make every rounding err low, the safe way.
//!
//! The distance in (I1) may be taken along the ground the targets can drive on: a target
//! never enters a cell of `S^o` (ground proven within `r_s` of an obstacle), so it must drive
//! round it, and its path is at least the straight distance. Every bound above is a straight
//! one, so it holds for the driven distance too; [`ReachSet::clear_around`] adds the bounds of
//! [`super::geodesic`], which go round `S^o`, and takes the larger.
//!
//! Fusion with another estimate of the same target intersects the cells (both hold the target)
//! and would take the larger reach (both bounds hold); the fleet exchanges cells only, so a
//! peer's set enters as an outer raster through [`ReachSet::intersect`].
//!
//! # Storage over a window around the set
//! A target's set is small next to the region, yet storing its reach for every cell of the
//! grid (4 bytes a cell: 16 MB for a 1 km square of 0.5 m cells) makes every copy and every
//! bound of it cost the whole region. A set given a margin ([`ReachSet::with_margin`]) stores
//! its reach only over a window: the cells of its bounding box and the margin on each side
//! (the columns rounded out to whole words of 64), cut when the reach is bounded by the set's
//! box ([`ReachSet::bound_by_box`]). Outside the window `τ` is the *far field* of the last
//! cut: with `B` the bounding box of the set's cells and `b_w` the clock then,
//! `τ_far(c) = ⌊(gap(c, B) + b_w) / unit⌋`, less two units for the rounding of its `f32`
//! arithmetic. Why (I1) holds for it:
//!
//! - at `b_w` every target lay in the closed square of one of the set's cells (I2), so in the
//!   rectangle of `B`, and `dist(p(b_w), square(c)) ≥ gap(c, B)`: (I1) holds at `b_w`, and
//!   (I1) is invariant in time;
//! - any lower reach keeps (I1), so the window may forget what clearing free ground had
//!   raised outside it: the set may then regrow there sooner, never lose a target.
//!
//! The window follows the set, and every cell the set holds stays in it:
//!
//! - before an advance lets the clock reach a cell outside the window, the window widens (by
//!   rows above and below, by words left and right) and its new cells take the far field.
//!   The far field never falls as a cell's gap to `B` grows, and its least value over a row
//!   (a column) is at the box's columns (rows), so once the rows and the columns next to the
//!   window are out of the clock's reach, every cell beyond is;
//! - an operation that writes the reach of cells outside the window (a measurement's window,
//!   a join) widens it first;
//! - clearing free ground raises the reach over the window's cells only, and counts the
//!   window's edges as not free, which only lowers the bounds.
//!
//! # A window around the UAV
//! The set of the targets no UAV has found yet, `X̄`, covers most of the region, so the same
//! cut by its box stores nothing less. An agent of a large fleet instead keeps `X̄`'s reach
//! over a window around its UAV ([`ReachSet::keep_window`], [`ReachSet::set_window`]): the
//! ground its guidance reads. Outside the window the set keeps a *summary*: for each block of
//! [`SUMMARY_BLOCK`] x [`SUMMARY_BLOCK`] cells one reach `σ(B)` that no cell of the block is
//! below, and every cell `c` outside the window counts with `τ(c) = σ(block(c))`. The set's
//! cells are kept over the whole grid (one bit a cell). Why (I1) and (I2) still hold:
//!
//! - **Folding.** A block leaving the window takes `σ ← max(σ, least τ of its cells)`: both
//!   are lower bounds of every cell's reach, so the larger is too (it is a fact about the
//!   targets, and (I1) is invariant in time). A block entering gives each cell `σ`.
//! - **Growth.** An advance adds, outside the window, every cell of each block whose `σ` the
//!   clock reached (where the advance's outer bound allows), so every cell the clock may
//!   have brought a target to is in the set, as (I1) requires; a block is looked at again
//!   when some of its cells leave the set, when its bound falls or when it leaves the window.
//! - **Clearing.** Ground proven free over a box that reaches outside the window raises the
//!   reach exactly over the box's part in the window (the window's sides count as not free,
//!   as for any window), and raises `σ` over the blocks outside it with a transform on the
//!   blocks: a block is free when every one of its cells is free, and the gap between two
//!   blocks' squares is at most the gap between any cell of one and any cell of the other,
//!   so `σ ← max(σ, ⌊(gap + b) / unit⌋)` keeps (I1) for each of its cells. Free cells leave
//!   the set wherever they lie (I2); a late fact removes a block's cells only when its raised
//!   `σ` is above the clock.
//! - **Lowering.** Any lower reach keeps (I1), so the summary may only lose tightness: a
//!   cell entering the window may rejoin the set sooner than it would have, never drop a
//!   target.
//!
//! Before the first [`ReachSet::set_window`] every cell is stored and the set is the one
//! without a window, bit for bit; a window that covers the grid keeps it so.
//!
//! ```
//! use sets::grid::GroundGrid;
//! use sets::raster::{CellBox, CellSet, ReachSet};
//!
//! let grid = GroundGrid::new(10.0, 0.5); // 40 x 40 cells
//! let mut set = ReachSet::full(&grid);
//! // Everything but the cell (20, 20) is proven free at the clock 0.
//! let mut free = CellSet::full(&grid);
//! free.set((20, 20), false);
//! set.clear(&grid, &free, &CellBox { x0: 0, y0: 0, x1: 39, y1: 39 });
//! assert_eq!(set.cells().count(), 1);
//! // One step of 1 m later the set holds the cells whose squares are within 1 m of its
//! // square: 3 more on each side along the axes, with rounded corners.
//! set.advance(1.0);
//! assert!(set.cells().contains((23, 20)) && !set.cells().contains((24, 20)));
//! assert!(set.cells().contains((22, 22)) && !set.cells().contains((23, 22)));
//! // Whole-cell dilation of the cell by 1 m gives the same cells; the difference is that
//! // the set remembers that (23, 20) is reached only just now, so it grows exactly next time.
//! set.advance(2.0);
//! assert!(set.cells().contains((25, 20)) && !set.cells().contains((26, 20)));
//! let twice = CellSet::from_cells(&grid, [(20, 20)]).dilate(&grid, 1.0).dilate(&grid, 1.0);
//! assert!(twice.contains((26, 20)) && twice.count() > set.cells().count());
//! ```

use std::cell::RefCell;
use std::ops::Range;

use super::distance::GapField;
use super::geodesic::{self, geodesic_gap_field};
use super::{CellBox, CellSet, common_rows};
use crate::grid::{CellIndex, GroundGrid};
use crate::math::Real;
use summary::Summary;
use window::{Far, FarField, Stored};

mod summary;
mod window;

pub use summary::BLOCK as SUMMARY_BLOCK;

/// The unit of reach, metres: `1/256` m, far below any cell and any step's motion.
pub const REACH_UNIT_M: Real = 1.0 / 256.0;

thread_local! {
    /// The distance transform's buffers, kept between the corrections of this thread's sets.
    static GAPS: RefCell<GapField> = RefCell::default();
}

/// An outer raster given word by word, for [`ReachSet::advance_within`]: a closure
/// `(cells, row, word) -> word` or a [`super::WordDilation`].
pub trait WordBound {
    /// Word `w` of row `iy` of the raster, from `cells`, the set's cells before the advance.
    fn word(&mut self, cells: &CellSet, iy: u32, w: usize) -> u64;

    /// False only when word `w` of row `iy` of the raster is certainly empty.
    fn may_hold(&self, _iy: u32, _w: usize) -> bool {
        true
    }

    /// False only when row `iy` of the raster is certainly empty.
    fn may_hold_row(&self, _iy: u32) -> bool {
        true
    }
}

impl<F: FnMut(&CellSet, u32, usize) -> u64> WordBound for F {
    fn word(&mut self, cells: &CellSet, iy: u32, w: usize) -> u64 {
        self(cells, iy, w)
    }
}

impl WordBound for super::WordDilation {
    fn word(&mut self, cells: &CellSet, iy: u32, w: usize) -> u64 {
        super::WordDilation::word(self, cells, iy, w)
    }

    fn may_hold(&self, iy: u32, w: usize) -> bool {
        super::WordDilation::may_hold(self, iy, w)
    }

    fn may_hold_row(&self, iy: u32) -> bool {
        super::WordDilation::may_hold_row(self, iy)
    }
}

/// Rounding margin of the conversions to reach units, in units.
const UNIT_MARGIN: Real = 1e-6;

/// An outer set on the [`GroundGrid`] that grows by the targets' motion without rounding it
/// out at every step (see the module docs for the invariants).
#[derive(Clone, Debug)]
pub struct ReachSet {
    cells: CellSet,
    /// `τ` per stored cell, row-major over the stored part ([`ReachSet::stored_rows`],
    /// [`ReachSet::stored_columns`]).
    reach: Vec<u32>,
    /// Per stored word: a lower bound of `τ` over the word's cells outside the set
    /// (`u32::MAX` when it has none), so that [`ReachSet::advance`] visits only the words the
    /// clock can change.
    pending: Vec<u32>,
    /// Per stored word: its last scan of the reach ([`Scan`]), valid until a reach of the
    /// word changes, so that a word the clock keeps reaching (cells held out by a bound) is not
    /// read again while nothing in it changed.
    scanned: Vec<Scan>,
    /// Rows `rows.0..rows.1` hold every cell of the set (some of them may be empty), so that
    /// queries and meets visit only those rows: a car's small set costs its rows, not the
    /// grid's. Meets tighten it; growth widens it.
    rows: (u32, u32),
    /// The rows and words whose reach is stored; they hold every cell of the set.
    stored: Stored,
    /// The reach of the cells outside the stored ones.
    far: Far,
    /// Cells around the set's box a cut of the window keeps ([`ReachSet::with_margin`]);
    /// `None`: every cell is stored.
    margin: Option<u32>,
    /// The motion clock `b` of the last [`ReachSet::advance`], metres.
    clock_m: Real,
}

/// One word's last scan: the cells whose reach was at most the clock then (`hits`) and the
/// least reach above it (`next`). While `next` is above the clock, no reach of the word lies
/// between the two clocks, so `hits` are still the cells reached. `next == 0` marks a stale
/// scan (no clock is below 0).
#[derive(Clone, Copy, Debug, Default)]
struct Scan {
    hits: u64,
    next: u32,
}

/// Equal cells, reach and clock, however each stores its reach (the pending bounds, the scans
/// and the rows are caches).
impl PartialEq for ReachSet {
    fn eq(&self, other: &Self) -> bool {
        if self.cells != other.cells || self.clock_m != other.clock_m {
            return false;
        }
        if self.stored == other.stored
            && matches!(self.far, Far::Nothing)
            && matches!(other.far, Far::Nothing)
        {
            return self.reach == other.reach;
        }
        let nx = self.cells.nx() as usize;
        let (mut mine, mut theirs) = (vec![0; nx], vec![0; nx]);
        (0..self.cells.ny()).all(|iy| {
            self.copy_reach_span(iy, 0, &mut mine);
            other.copy_reach_span(iy, 0, &mut theirs);
            mine == theirs
        })
    }
}

/// Reach units of the clock: the largest reach a cell can have and still be reached.
fn reached_units(clock_m: Real) -> u32 {
    (clock_m / REACH_UNIT_M + UNIT_MARGIN)
        .floor()
        .clamp(0.0, Real::from(u32::MAX)) as u32
}

impl ReachSet {
    /// Every cell of `grid`, nothing known, clock 0.
    pub fn full(grid: &GroundGrid) -> Self {
        Self::storing_every_row(CellSet::full(grid), 0.0)
    }

    /// [`ReachSet::full`] kept over a window ([`ReachSet::keep_window`]) that holds no cell
    /// yet: every block's bound is 0 and none is settled, so the first
    /// [`ReachSet::set_window`] gives it exactly the set `full(grid).keep_window()` gets from
    /// the same window. It never holds the reach of the whole grid, 4 bytes a cell (64 MB for
    /// a 2 km region of 0.5 m cells), which an agent kept over a window would otherwise
    /// allocate once at its start.
    pub fn full_outside_window(grid: &GroundGrid) -> Self {
        let cells = CellSet::full(grid);
        Self {
            reach: Vec::new(),
            pending: Vec::new(),
            scanned: Vec::new(),
            rows: rows_of(&cells),
            stored: Stored::nothing(),
            far: Far::Summary(Box::new(Summary::new(cells.nx(), cells.ny()))),
            margin: None,
            cells,
            clock_m: 0.0,
        }
    }

    /// A set of `cells` at the clock `clock_m` (0 when not finite) that stores every row, with
    /// the reach 0 and the pending bounds `u32::MAX`: the callers fill them in.
    fn storing_every_row(cells: CellSet, clock_m: Real) -> Self {
        let n = cells.nx() as usize * cells.ny() as usize;
        let words = cells.words_per_row() * cells.ny() as usize;
        Self {
            reach: vec![0; n],
            pending: vec![u32::MAX; words],
            scanned: vec![Scan::default(); words],
            rows: rows_of(&cells),
            stored: Stored::everything(&cells),
            far: Far::Nothing,
            margin: None,
            cells,
            clock_m: if clock_m.is_finite() { clock_m } else { 0.0 },
        }
    }

    /// A set of `cells` at clock 0 whose reach is unknown (0): its other cells join it at the
    /// first advance.
    pub fn with_cells(cells: CellSet) -> Self {
        let mut set = Self::storing_every_row(cells, 0.0);
        set.rebuild_pending();
        set
    }

    /// A set of `cells` at the clock `clock_m` that remembers nothing else: the reach of each
    /// cell outside is its gap to the nearest of `cells`, raised by the clock, as
    /// [`ReachSet::clear`] would set it. (I1) holds because by (I2) every target lies in the
    /// closed square of one of `cells` at that clock. What a checkpoint restores: the set then
    /// grows from `cells` by the motion since, without the sub-cell reach it had.
    pub fn from_cells_at(grid: &GroundGrid, cells: CellSet, clock_m: Real) -> Self {
        let mut set = Self::storing_every_row(cells, clock_m);
        let whole = CellBox {
            x0: 0,
            y0: 0,
            x1: set.cells.nx().saturating_sub(1),
            y1: set.cells.ny().saturating_sub(1),
        };
        if set.cells.nx() > 0 && set.cells.ny() > 0 {
            let inside = set.cells.window_flags(&whole, false);
            let clock = set.clock_m;
            set.raise_outside(grid, &whole, &inside, clock);
        }
        set.rebuild_pending();
        set
    }

    /// The cells the set holds now.
    pub fn cells(&self) -> &CellSet {
        &self.cells
    }

    /// Whether cell `c` is in the set.
    pub fn contains(&self, c: CellIndex) -> bool {
        self.cells.contains(c)
    }

    /// Rows that hold every cell of the set (some may be empty): what the queries below visit.
    pub fn rows(&self) -> std::ops::Range<u32> {
        self.rows.0..self.rows.1
    }

    /// The words of the set's [`ReachSet::rows`].
    fn words(&self) -> &[u64] {
        self.cells.stored_words(self.rows()).1
    }

    /// Whether the set has no cell.
    pub fn is_empty(&self) -> bool {
        self.words().iter().all(|&w| w == 0)
    }

    /// Number of cells in the set.
    pub fn count(&self) -> u64 {
        self.words().iter().map(|w| u64::from(w.count_ones())).sum()
    }

    /// Area of the set, m².
    pub fn area(&self, grid: &GroundGrid) -> Real {
        self.count() as Real * grid.cell_area()
    }

    /// Whether the set shares a cell with `other` (on the same grid).
    pub fn intersects(&self, other: &CellSet) -> bool {
        debug_assert!(self.cells.same_shape(other));
        self.cells.intersects(other)
    }

    /// The smallest box holding every cell of the set, `None` when empty.
    pub fn bounding_box(&self) -> Option<CellBox> {
        self.cells.bounding_box_within(self.rows())
    }

    /// Widens the rows to hold row `iy`.
    fn hold_row(&mut self, iy: u32) {
        self.rows = if self.rows.0 < self.rows.1 {
            (self.rows.0.min(iy), self.rows.1.max(iy + 1))
        } else {
            (iy, iy + 1)
        };
    }

    /// The motion clock of the last advance, metres.
    pub fn clock_m(&self) -> Real {
        self.clock_m
    }

    /// A lower bound of the distance, metres, between cell `c`'s square and every target the
    /// set holds, at the current clock (0 for cells the targets may reach; `None` outside the
    /// grid).
    pub fn clearance_m(&self, (ix, iy): CellIndex) -> Option<Real> {
        if ix >= self.cells.nx() || iy >= self.cells.ny() {
            return None;
        }
        let tau = self.reach_at(ix, iy);
        Some((Real::from(tau) * REACH_UNIT_M - self.clock_m).max(0.0))
    }

    /// Index into `reach` of the stored cell `(ix, iy)`.
    fn index(&self, ix: u32, iy: u32) -> usize {
        (iy - self.stored.rows.0) as usize * self.stride()
            + (ix - self.stored_columns().start) as usize
    }

    /// Index into `pending` and `scanned` of the stored word `w` of row `iy`.
    fn slot(&self, iy: u32, w: usize) -> usize {
        (iy - self.stored.rows.0) as usize * self.stored_words() + (w - self.stored.words.0)
    }

    /// The stored words of the set, `(row, word)`, row after row.
    fn stored_word_indices(&self) -> impl Iterator<Item = (u32, usize)> + use<> {
        let words = self.stored.word_range();
        self.stored_rows()
            .flat_map(move |iy| words.clone().map(move |w| (iy, w)))
    }

    /// The cells of word `w` of the grid's rows: `w * 64..` up to 64 of them, cut at `nx`.
    fn word_cells(&self, w: usize) -> usize {
        64.min(self.cells.nx() as usize - w * 64)
    }

    /// Moves the clock to `clock_m` (`v_max` times the time since the clock's origin): every
    /// cell the targets may have reached by then joins the set. A clock earlier than the
    /// current one, or not a number, changes nothing.
    pub fn advance(&mut self, clock_m: Real) {
        if clock_m.is_nan() || clock_m <= self.clock_m {
            return;
        }
        self.clock_m = clock_m;
        let reached = reached_units(clock_m);
        self.widen_for(reached);
        let mut grown_rows: Option<(u32, u32)> = None;
        self.scan_due(
            reached,
            |_| false,
            |_, _| false,
            |cells, iy, w, bits| {
                cells.row_mut(iy)[w] |= bits;
                if bits != 0 {
                    grown_rows = Some(grown_rows.map_or((iy, iy), |(a, _)| (a, iy)));
                }
            },
        );
        if let Some((first, last)) = grown_rows {
            self.hold_row(first);
            self.hold_row(last);
        }
        let outside = self.outside_growth(reached, None);
        self.grow_outside(outside);
    }

    /// [`ReachSet::advance`], then [`ReachSet::intersect`] with an outer raster `bound` of the
    /// set's targets that holds every cell of the set (a dilation of its cells by the motion
    /// since the last clock), given word by word ([`WordBound`]) from the set's cells before
    /// the advance. Only the words the clock adds cells to are asked for, so a bound that is
    /// costly over the whole grid (a dilation, through [`super::WordDilation`]) costs only
    /// where the set grows; a word the bound says is empty ([`WordBound::may_hold`]) is not
    /// even read, since none of its cells could join.
    pub fn advance_within(&mut self, clock_m: Real, mut bound: impl WordBound) {
        if clock_m.is_nan() || clock_m <= self.clock_m {
            return;
        }
        self.clock_m = clock_m;
        let reached = reached_units(clock_m);
        self.widen_for(reached);
        // Every word's new cells first, from the cells before the advance, then the bound of
        // those words, read on the same unchanged cells. A skipped word keeps its pending
        // bound (at most the clock), so the next advance looks at it again.
        let mut grown: Vec<(u32, usize, u64)> = Vec::new();
        self.scan_due(
            reached,
            |iy| !bound.may_hold_row(iy),
            |iy, w| !bound.may_hold(iy, w),
            |cells, iy, w, bits| {
                let fresh = bits & !cells.row(iy)[w];
                if fresh != 0 {
                    grown.push((iy, w, fresh));
                }
            },
        );
        for &mut (iy, w, ref mut fresh) in &mut grown {
            let keep = *fresh & bound.word(&self.cells, iy, w);
            if keep != *fresh {
                // Cells reached but outside the bound stay out: the pending bound drops to 0
                // so that the next advance settles the word, as `intersect` does.
                let slot = self.slot(iy, w);
                self.pending[slot] = 0;
            }
            *fresh = keep;
        }
        let outside = self.outside_growth(reached, Some(&mut bound));
        for (iy, w, fresh) in grown {
            self.cells.row_mut(iy)[w] |= fresh;
            if fresh != 0 {
                self.hold_row(iy);
            }
        }
        self.grow_outside(outside);
    }

    /// `cells ← cells ∩ outer`, for an outer raster of the set's targets (a peer's set, a
    /// conservative dilation of an earlier set). The reach is unchanged.
    pub fn intersect(&mut self, outer: &CellSet) {
        debug_assert!(self.cells.same_shape(outer));
        self.remove_where(0..self.cells.ny(), |cells, iy, w| {
            cells.row(iy)[w] & !outer.row(iy)[w]
        });
    }

    /// Removes ground proven free (`free`, an inner raster) without raising the reach: the
    /// cells leave the set until the clock moves on.
    pub fn remove(&mut self, free: &CellSet) {
        debug_assert!(self.cells.same_shape(free));
        // Rows `free` does not store hold nothing to remove.
        self.remove_where(free.stored_rows(), |cells, iy, w| {
            cells.row(iy)[w] & free.row(iy)[w]
        });
    }

    /// `cells ← cells ∪ extra`, forgetting what the reach knew of the added cells (their
    /// reach drops to 0, so they stay until proven free): the safe fallback when two
    /// estimates of one target disagree.
    pub fn join(&mut self, extra: &CellSet) {
        debug_assert!(self.cells.same_shape(extra));
        let Some(b) = extra.bounding_box() else {
            return;
        };
        self.store(Stored::of_box(&b));
        for (ix, iy) in extra.iter() {
            if !self.cells.contains((ix, iy)) {
                let (at, slot) = (self.index(ix, iy), self.slot(iy, ix as usize / 64));
                self.reach[at] = 0;
                self.scanned[slot] = Scan::default();
            }
        }
        self.cells.or_assign(extra);
        self.hold_row(b.y0);
        self.hold_row(b.y1);
    }

    /// Removes ground proven free at the current clock (`free`, an inner raster: no target in
    /// the closed square of any of its cells) and raises the reach of the free cells inside
    /// `window` to their gap from the nearest cell that is not free. Free cells outside
    /// `window` only leave the set; the cells around the window count as not free, which only
    /// lowers the bounds.
    pub fn clear(&mut self, grid: &GroundGrid, free: &CellSet, window: &CellBox) {
        debug_assert!(self.cells.same_shape(free));
        if let Some((w, seeds)) = self.window_seeds(free, window) {
            self.raise_outside(grid, &w, &seeds, self.clock_m);
        }
        self.raise_summary(grid, free, window, self.clock_m);
        self.remove(free);
    }

    /// As [`ReachSet::clear`] for ground proven free at an earlier clock `then_m` (a late
    /// measurement): the free cells inside `window` get the reach of their gap at `then_m`,
    /// `τ ← max(τ, ⌊(gap + b_then) / unit⌋)`, which keeps (I1) at every later clock, and a
    /// cell leaves the set only when its reach is then above the current clock: by (I1) no
    /// target is in its closed square now. The other free cells stay, since a target may have
    /// driven into them since. At the set's own clock this is [`ReachSet::clear`]; a clock
    /// later than the set's (a fact from a step the set has not reached) or not a number
    /// changes nothing.
    pub fn clear_since(
        &mut self,
        grid: &GroundGrid,
        free: &CellSet,
        window: &CellBox,
        then_m: Real,
    ) {
        match then_m.partial_cmp(&self.clock_m) {
            Some(std::cmp::Ordering::Equal) => self.clear(grid, free, window),
            Some(std::cmp::Ordering::Less) => {
                debug_assert!(self.cells.same_shape(free));
                if let Some((w, seeds)) = self.window_seeds(free, window) {
                    self.raise_outside(grid, &w, &seeds, then_m);
                    self.drop_unreached(&w);
                }
                self.raise_summary(grid, free, window, then_m);
            }
            _ => {}
        }
    }

    /// As [`ReachSet::clear`], and the reach of the free cells inside `window` is also raised
    /// to the length of the shortest way round `blocked` from the nearest cell that is not
    /// free ([`super::geodesic`]): `blocked` is ground no target ever enters (no target in
    /// the closed square of any of its cells, at any time), which the targets must drive
    /// around. Distances along such paths are at least the straight ones, so (I1) holds with
    /// them in place of the straight distance, and every other operation keeps it.
    pub fn clear_around(
        &mut self,
        grid: &GroundGrid,
        free: &CellSet,
        blocked: &CellSet,
        window: &CellBox,
    ) {
        debug_assert!(self.cells.same_shape(free) && self.cells.same_shape(blocked));
        if let Some((w, seeds)) = self.window_seeds(free, window) {
            self.raise_outside(grid, &w, &seeds, self.clock_m);
            let walls = blocked.window_flags(&w, false);
            if walls.contains(&true) {
                let sources: Vec<bool> = seeds.iter().zip(&walls).map(|(s, b)| *s && !*b).collect();
                if let Some(field) = geodesic_gap_field(&w, &sources, &walls) {
                    self.raise_around(grid, &w, &seeds, &walls, &field);
                }
            }
        }
        self.raise_summary(grid, free, window, self.clock_m);
        self.remove(free);
    }

    /// The window grown by 2 cells and clamped to the grid and to the stored cells, and its
    /// seeds: the cells that are not free, and the cells of every window side inside the grid
    /// (they stand for every cell beyond it, so counting them as not free keeps each gap at
    /// most the true one).
    fn window_seeds(&self, free: &CellSet, window: &CellBox) -> Option<(CellBox, Vec<bool>)> {
        let mut w = clamp_box(window, 2, &self.cells)?;
        let columns = self.stored_columns();
        (w.y0, w.y1) = (
            w.y0.max(self.stored.rows.0),
            w.y1.min(self.stored.rows.1.checked_sub(1)?),
        );
        (w.x0, w.x1) = (
            w.x0.max(columns.start),
            w.x1.min(columns.end.checked_sub(1)?),
        );
        if w.y0 > w.y1 || w.x0 > w.x1 {
            return None;
        }
        let (nx, ny) = (self.cells.nx(), self.cells.ny());
        let mut seeds = free.window_flags(&w, false);
        let width = (w.x1 - w.x0 + 1) as usize;
        let height = seeds.len() / width;
        let (left, right) = (w.x0 > 0, w.x1 + 1 < nx);
        for (y, row) in seeds.chunks_exact_mut(width).enumerate() {
            let edge_row = (y == 0 && w.y0 > 0) || (y + 1 == height && w.y1 + 1 < ny);
            for seed in row.iter_mut() {
                *seed = !*seed || edge_row;
            }
            row[0] |= left;
            row[width - 1] |= right;
        }
        Some((w, seeds))
    }

    /// Raises `τ` of every cell of `window` that is neither a seed nor blocked to the geodesic
    /// bound of its `field` value ([`super::geodesic::gap_cells`]); a cell no seed reaches
    /// can hold no target while the clock stands, and gets the largest reach.
    fn raise_around(
        &mut self,
        grid: &GroundGrid,
        window: &CellBox,
        seeds: &[bool],
        blocked: &[bool],
        field: &[u32],
    ) {
        self.forget_scans(window);
        let w = (window.x1 - window.x0 + 1) as usize;
        let (unit, clock) = (grid.cell_m / REACH_UNIT_M, self.clock_m / REACH_UNIT_M);
        for (k, &d) in field.iter().enumerate() {
            if seeds[k] || blocked[k] {
                continue;
            }
            let tau = match geodesic::gap_cells(d) {
                // Truncation is the floor here (non-negative); `as` saturates.
                Some(gap) => (gap * unit + clock - UNIT_MARGIN).max(0.0) as u32,
                None => u32::MAX - 1,
            };
            let (ix, iy) = (window.x0 + (k % w) as u32, window.y0 + (k / w) as u32);
            let at = self.index(ix, iy);
            let slot = &mut self.reach[at];
            *slot = (*slot).max(tau.min(u32::MAX - 1));
        }
    }

    /// Restricts the set to an outer raster `outer` of its targets at the current clock (a
    /// measurement) and raises the reach of the cells within `margin` cells of `outer`'s
    /// bounding box to their exact gap from `outer`. When the set reached beyond that window,
    /// the reach of every other cell is raised to its gap from the bounding box
    /// ([`ReachSet::bound_by_box`]).
    pub fn restrict(&mut self, grid: &GroundGrid, outer: &CellSet, margin: u32) {
        debug_assert!(self.cells.same_shape(outer));
        let Some(window) = outer
            .bounding_box()
            .and_then(|b| clamp_box(&b, margin, &self.cells))
        else {
            self.intersect(outer);
            return;
        };
        let was_wider = self
            .bounding_box()
            .is_some_and(|b| !(window.contains((b.x0, b.y0)) && window.contains((b.x1, b.y1))));
        self.store(Stored::of_box(&window));
        self.raise_outside(
            grid,
            &window,
            &outer.window_flags(&window, false),
            self.clock_m,
        );
        self.intersect(outer);
        if was_wider {
            self.bound_by_box(grid);
        }
    }

    /// As [`ReachSet::restrict`] for a measurement at an earlier clock `then_m` (the targets
    /// lay in `outer` then): the cells within `margin` cells of `outer`'s box get the reach of
    /// their gap to `outer` at `then_m` ([`ReachSet::clear_since`] says why that holds), the
    /// cells whose reach is then above the current clock leave the set, and so do the cells
    /// farther from `outer` than the motion since (outside its dilation by `b_now - b_then`,
    /// an outer raster of the targets now). At the set's own clock this is
    /// [`ReachSet::restrict`]; a later clock or one that is not a number changes nothing, and
    /// so does an empty `outer` (it would prove nothing but a broken measurement).
    pub fn restrict_since(
        &mut self,
        grid: &GroundGrid,
        outer: &CellSet,
        margin: u32,
        then_m: Real,
    ) {
        debug_assert!(self.cells.same_shape(outer));
        match then_m.partial_cmp(&self.clock_m) {
            Some(std::cmp::Ordering::Equal) => return self.restrict(grid, outer, margin),
            Some(std::cmp::Ordering::Less) => {}
            _ => return,
        }
        let Some(window) = outer
            .bounding_box()
            .and_then(|b| clamp_box(&b, margin, &self.cells))
        else {
            return;
        };
        let was_wider = self
            .bounding_box()
            .is_some_and(|b| !(window.contains((b.x0, b.y0)) && window.contains((b.x1, b.y1))));
        self.store(Stored::of_box(&window));
        self.raise_outside(grid, &window, &outer.window_flags(&window, false), then_m);
        self.drop_unreached(&window);
        self.intersect(&outer.dilate(grid, self.clock_m - then_m));
        if was_wider {
            self.bound_by_box(grid);
        }
    }

    /// Removes the cells of `window`'s rows whose reach is above the current clock: by (I1)
    /// they hold no target now. (A cell joins the set only once the clock reaches it, so only
    /// a reach raised since, by a late fact, puts a cell of the set beyond the clock.)
    fn drop_unreached(&mut self, window: &CellBox) {
        let reached = reached_units(self.clock_m);
        let last = window.y1.min(self.stored.rows.1.saturating_sub(1));
        let words = self.stored_words_of(window);
        let mut gone: Vec<(u32, usize, u64)> = Vec::new();
        for iy in window.y0.max(self.stored.rows.0)..=last {
            for w in words.clone() {
                let word = self.cells.row(iy)[w];
                if word == 0 {
                    continue;
                }
                let base = self.index(w as u32 * 64, iy);
                let (hits, _) = reached_bits(&self.reach[base..base + self.word_cells(w)], reached);
                let out = word & !hits;
                if out != 0 {
                    gone.push((iy, w, out));
                }
            }
        }
        if !gone.is_empty() {
            self.remove_where(window.y0..last + 1, |_, iy, w| {
                gone.binary_search_by(|&(y, x, _)| (y, x).cmp(&(iy, w)))
                    .map_or(0, |k| gone[k].2)
            });
        }
    }

    /// Raises the reach of every cell to the gap between its square and the bounding box of
    /// the set's cells (which hold the targets, so they are no nearer): the far field of a
    /// small set, so that it regrows as a rounded box rather than all at once. A set with a
    /// margin ([`ReachSet::with_margin`]) then stores the cells within the margin of its box
    /// only, and this bound is its reach elsewhere.
    pub fn bound_by_box(&mut self, grid: &GroundGrid) {
        let Some(b) = self.bounding_box() else {
            return;
        };
        self.bound_by(FarField::new(grid, b, self.clock_m), &b);
    }

    /// Raises `τ` of every cell of `window` outside the outer raster `inside` (of the targets
    /// at the clock `clock_m`) to the gap between its square and the nearest square of
    /// `inside` within the window, plus that clock (the caller makes sure no cell of `inside`
    /// outside the window is nearer).
    fn raise_outside(
        &mut self,
        grid: &GroundGrid,
        window: &CellBox,
        inside: &[bool],
        clock_m: Real,
    ) {
        self.forget_scans(window);
        GAPS.with_borrow_mut(|field| {
            let w = (window.x1 - window.x0 + 1) as usize;
            let (unit, clock) = (grid.cell_m / REACH_UNIT_M, clock_m / REACH_UNIT_M);
            field.compute_rows(window, inside, |y, gap_row| {
                let seed_row = &inside[y * w..(y + 1) * w];
                let start = self.index(window.x0, window.y0 + y as u32);
                let reach = &mut self.reach[start..start + w];
                // Without branches, so that the loop runs at the speed of its arithmetic: a seed
                // keeps its reach, and an unreached cell (`gap2` is `distance::UNREACHED`, whose
                // root times the unit is far above `u32::MAX`) gets the largest.
                for ((slot, &gap2), &seed) in reach.iter_mut().zip(gap_row).zip(seed_row) {
                    // Truncation is the floor here (non-negative); `as` saturates.
                    let tau = ((gap2 as Real).sqrt() * unit + clock - UNIT_MARGIN).max(0.0) as u32;
                    let raised = (*slot).max(tau.min(u32::MAX - 1));
                    *slot = if seed { *slot } else { raised };
                }
            });
        });
    }

    /// Scans every word whose pending bound the clock `reached` (in reach units) has come
    /// to, but those `skip` names and those of the rows `skip_row` names, records its next
    /// pending bound, and hands `visit` the set's cells, the word's row and index, and the
    /// word's cells reached by then.
    fn scan_due(
        &mut self,
        reached: u32,
        skip_row: impl Fn(u32) -> bool,
        skip: impl Fn(u32, usize) -> bool,
        mut visit: impl FnMut(&mut CellSet, u32, usize, u64),
    ) {
        for iy in self.stored_rows() {
            if skip_row(iy) {
                continue;
            }
            for w in self.stored.word_range() {
                let slot = self.slot(iy, w);
                if self.pending[slot] > reached || skip(iy, w) {
                    continue;
                }
                let base = self.index(w as u32 * 64, iy);
                let (bits, next) = self.scan(slot, base..base + self.word_cells(w), reached);
                self.pending[slot] = next;
                visit(&mut self.cells, iy, w, bits);
            }
        }
    }

    /// The reach of the cells of word `slot` (at `range` of the reach) the clock `reached`
    /// reaches, as bits, and the least reach above it: from the word's last scan while that
    /// still holds, else read and remembered.
    fn scan(&mut self, slot: usize, range: std::ops::Range<usize>, reached: u32) -> (u64, u32) {
        let last = self.scanned[slot];
        if last.next > reached {
            return (last.hits, last.next);
        }
        let (hits, next) = reached_bits(&self.reach[range], reached);
        self.scanned[slot] = Scan { hits, next };
        (hits, next)
    }

    /// Marks the scans of the words of `window` stale (their reach is about to change).
    fn forget_scans(&mut self, window: &CellBox) {
        let words = self.stored_words_of(window);
        if words.is_empty() {
            return;
        }
        for iy in
            window.y0.max(self.stored.rows.0)..=window.y1.min(self.stored.rows.1.saturating_sub(1))
        {
            let (first, last) = (self.slot(iy, words.start), self.slot(iy, words.end - 1));
            self.scanned[first..=last].fill(Scan::default());
        }
    }

    /// Removes the bits `remove(cells, row, word)` of every word of the set's rows among
    /// `within` (the others hold no cell to remove); their pending bound drops to 0 (always a
    /// lower bound), so the next advance settles those words. The rows shrink to those still
    /// holding cells, as far as the rows visited tell.
    fn remove_where(&mut self, within: Range<u32>, remove: impl Fn(&CellSet, u32, usize) -> u64) {
        let visit = common_rows(self.rows(), within);
        if visit.is_empty() {
            return;
        }
        // A target's set has no cell outside its stored words; an undetected set kept over a
        // window may have cells in every word.
        let words = if self.far.holds_outside() {
            0..self.cells.words_per_row()
        } else {
            self.stored.word_range()
        };
        let mut held: Option<(u32, u32)> = None;
        for iy in visit.clone() {
            let mut any = 0;
            for w in words.clone() {
                let gone = remove(&self.cells, iy, w);
                if gone != 0 {
                    self.cells.row_mut(iy)[w] &= !gone;
                    if self.stores(w as u32 * 64, iy) {
                        let slot = self.slot(iy, w);
                        self.pending[slot] = 0;
                    } else {
                        self.unsettle_removed(iy, w, gone);
                    }
                }
                any |= self.cells.row(iy)[w];
            }
            if any != 0 {
                held = Some(held.map_or((iy, iy), |(a, _)| (a, iy)));
            }
        }
        // Rows before and after the visited ones keep whatever they held.
        let (before, after) = (self.rows.0 < visit.start, self.rows.1 > visit.end);
        let first = match held {
            _ if before => Some(self.rows.0),
            Some((a, _)) => Some(a),
            None => after.then_some(visit.end),
        };
        let end = match held {
            _ if after => Some(self.rows.1),
            Some((_, b)) => Some(b + 1),
            None => before.then_some(visit.start),
        };
        self.rows = first.zip(end).unwrap_or((0, 0));
        self.cells.trim_rows();
    }

    /// The set as parts for snapshots ([`ReachSet::from_parts`]): its cells, the least reach
    /// and every cell's reach above it, row-major.
    pub fn to_parts(&self) -> (CellSet, u32, Vec<u32>) {
        let nx = self.cells.nx() as usize;
        let mut reach = vec![0; nx * self.cells.ny() as usize];
        if nx > 0 {
            for (iy, row) in (0..self.cells.ny()).zip(reach.chunks_exact_mut(nx)) {
                self.copy_reach_span(iy, 0, row);
            }
        }
        let base = reach.iter().copied().min().unwrap_or(0);
        reach.iter_mut().for_each(|t| *t -= base);
        (self.cells.clone(), base, reach)
    }

    /// Rebuilds a set from [`ReachSet::to_parts`] with the clock at `clock_m`; `None` when the
    /// lengths do not match the cells' grid.
    pub fn from_parts(cells: CellSet, base: u32, relative: &[u32], clock_m: Real) -> Option<Self> {
        if relative.len() != cells.nx() as usize * cells.ny() as usize {
            return None;
        }
        let mut set = Self::storing_every_row(cells, clock_m);
        for (tau, &d) in set.reach.iter_mut().zip(relative) {
            *tau = d.saturating_add(base);
        }
        set.rebuild_pending();
        Some(set)
    }

    /// Recomputes every word's pending reach exactly.
    fn rebuild_pending(&mut self) {
        for (iy, w) in self.stored_word_indices() {
            let word = self.cells.row(iy)[w];
            let base = self.index(w as u32 * 64, iy);
            let slot = self.slot(iy, w);
            self.pending[slot] = (0..self.word_cells(w))
                .filter(|b| word >> b & 1 == 0)
                .map(|b| self.reach[base + b])
                .min()
                .unwrap_or(u32::MAX);
        }
    }
}

/// The cells of a word (at most 64 reach values) the clock `reached` reaches, as bits, and the
/// least reach of the others (`u32::MAX` when none), without branches so that it vectorises.
fn reached_bits(reach: &[u32], reached: u32) -> (u64, u32) {
    match <&[u32; 64]>::try_from(reach) {
        Ok(word) => reached_bits_64(word, reached),
        Err(_) => reached_bits_of_any(reach, reached),
    }
}

/// [`reached_bits`] of at most 64 cells, one at a time.
fn reached_bits_of_any(reach: &[u32], reached: u32) -> (u64, u32) {
    let mut bits = 0u64;
    let mut next = u32::MAX;
    for (b, &tau) in reach.iter().enumerate() {
        let hit = tau <= reached;
        bits |= u64::from(hit) << b;
        next = next.min(if hit { u32::MAX } else { tau });
    }
    (bits, next)
}

/// [`reached_bits`] of a whole word, in fixed lanes the compiler vectorises.
fn reached_bits_64(reach: &[u32; 64], reached: u32) -> (u64, u32) {
    let mut bits = 0u64;
    for (k, lane) in reach.chunks_exact(8).enumerate() {
        let mut byte = 0u8;
        for (j, &tau) in lane.iter().enumerate() {
            byte |= u8::from(tau <= reached) << j;
        }
        bits |= u64::from(byte) << (8 * k);
    }
    let mut next = [u32::MAX; 8];
    for lane in reach.chunks_exact(8) {
        for (n, &tau) in next.iter_mut().zip(lane) {
            *n = (*n).min(if tau <= reached { u32::MAX } else { tau });
        }
    }
    (bits, next.into_iter().fold(u32::MAX, u32::min))
}

/// The rows holding the cells of `cells`, as `ReachSet::rows` keeps them.
fn rows_of(cells: &CellSet) -> (u32, u32) {
    cells
        .row_range()
        .map_or((0, 0), |(first, last)| (first, last + 1))
}

/// Whole cells strictly between index `i` and the span `lo..=hi` (0 inside or next to it).
fn gap_cells(i: u32, lo: u32, hi: u32) -> u32 {
    if i < lo {
        lo - i - 1
    } else {
        i.saturating_sub(hi).saturating_sub(1)
    }
}

/// `bbox` grown by `margin` cells on every side and clamped to the set's grid; `None` for an
/// inverted box or an empty grid.
fn clamp_box(bbox: &CellBox, margin: u32, cells: &CellSet) -> Option<CellBox> {
    if bbox.x0 > bbox.x1 || bbox.y0 > bbox.y1 || cells.nx() == 0 || cells.ny() == 0 {
        return None;
    }
    let b = CellBox {
        x0: bbox.x0.saturating_sub(margin),
        y0: bbox.y0.saturating_sub(margin),
        x1: bbox.x1.saturating_add(margin).min(cells.nx() - 1),
        y1: bbox.y1.saturating_add(margin).min(cells.ny() - 1),
    };
    (b.x0 <= b.x1 && b.y0 <= b.y1).then_some(b)
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    proptest! {
        /// The vectorised word scan gives the bits and the next reach of the plain one,
        /// around the clock and at the ends of the range.
        #[test]
        fn the_word_scan_in_lanes_is_the_plain_scan(
            reach in prop::collection::vec(
                prop_oneof![990u32..1010, Just(0), Just(u32::MAX - 1), Just(u32::MAX)],
                64,
            ),
            reached in prop_oneof![995u32..1005, Just(0), Just(u32::MAX)],
        ) {
            let word: &[u32; 64] = reach.as_slice().try_into().expect("64 cells");
            prop_assert_eq!(reached_bits_64(word, reached), reached_bits_of_any(&reach, reached));
        }
    }
}
