//! Bit-raster sets on the [`GroundGrid`]: the representation of every guaranteed set.
//!
//! A [`CellSet`] is `ny` rows of `u64` words, bit `ix % 64` of word `ix / 64` of row `iy` set
//! when cell `(ix, iy)` belongs to the set. The algebra keeps the guarantee when used by the
//! rules of docs/design.md §3:
//! - a set that must *contain* something is rasterised [`Coverage::Outer`] (every cell the true
//!   set touches); a set *proven free* is rasterised [`Coverage::Inner`] (only cells wholly
//!   inside);
//! - `outer \ inner`, `outer ∩ outer` and `outer ∪ outer` are outer;
//! - [`CellSet::dilate`] contains every point within the radius of the set;
//! - a [`ReachSet`] is an outer set that grows by the targets' motion without rounding it out
//!   to whole cells at every step ([`reach`] argues its guarantee), using the exact gaps
//!   between cell squares of [`distance`] and, around ground no car enters, the lower bounds
//!   of [`geodesic`].
//!
//! The operations live one per file: `polygon` and `disc` rasterise shapes, `dilate` grows a
//! set, `coarse` coarsens it to blocks (a block in the set when any of its cells is), `extent` measures and crops it, `encode` turns it into an [`EncodedSet`] and back,
//! `distance` measures gaps between cells, `geodesic` the ways round what cannot be crossed,
//! and `reach` keeps sets that grow exactly.
//!
//! ```
//! use sets::grid::GroundGrid;
//! use sets::math::Point2;
//! use sets::raster::{CellSet, Coverage};
//!
//! let grid = GroundGrid::new(10.0, 0.5);
//! let mut seen = CellSet::empty(&grid);
//! seen.fill_disc(&grid, Point2::new(0.0, 0.0), 3.0, Coverage::Outer);
//! let grown = seen.dilate(&grid, 1.0);
//! assert!(seen.is_subset_of(&grown));
//! let back = CellSet::decode(&grid, &grown.encode()).unwrap();
//! assert_eq!(back, grown);
//! ```

mod coarse;
pub mod delta;
mod dilate;
mod disc;
pub mod distance;
mod encode;
mod extent;
pub mod geodesic;
mod polygon;
pub mod reach;

use std::ops::Range;

use serde::{Deserialize, Serialize};

use crate::grid::{CellIndex, GroundGrid};
use crate::math::Real;

pub use dilate::WordDilation;
pub use polygon::polygon_is_finite;
pub use reach::{REACH_UNIT_M, ReachSet, WordBound};

/// How a continuous shape is turned into cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Coverage {
    /// Every cell whose closed square meets the shape (a superset).
    Outer,
    /// Only cells whose closed square lies wholly inside the shape (a subset).
    Inner,
}

/// An inclusive rectangle of cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CellBox {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// Last column (inclusive).
    pub x1: u32,
    /// Last row (inclusive).
    pub y1: u32,
}

impl CellBox {
    /// Whether cell `(ix, iy)` lies in the box.
    pub fn contains(&self, (ix, iy): CellIndex) -> bool {
        ix >= self.x0 && ix <= self.x1 && iy >= self.y0 && iy <= self.y1
    }

    /// Number of cells in the box (0 when inverted), in `u64` so no grid can overflow it.
    pub fn cell_count(&self) -> u64 {
        if self.x0 > self.x1 || self.y0 > self.y1 {
            return 0;
        }
        (u64::from(self.x1 - self.x0) + 1) * (u64::from(self.y1 - self.y0) + 1)
    }
}

/// The tolerance of the geometric tests at coordinate magnitude `scale`: far above the
/// rounding of f64 arithmetic on such numbers, far below any cell size. Outer rasterisation
/// widens shapes by it, inner rasterisation narrows them by it.
fn margin(scale: Real) -> Real {
    1e-9 * (1.0 + scale.abs())
}

/// The largest coordinate magnitude of the grid's corners, the floor of every margin.
fn grid_scale(grid: &GroundGrid) -> Real {
    let b = grid.bounds();
    b.min
        .x
        .abs()
        .max(b.min.y.abs())
        .max(b.max.x.abs())
        .max(b.max.y.abs())
}

/// The words of a row span ([`CellSet::fill_row_span`]) and the masks of its end words.
struct SpanWords {
    w0: usize,
    w1: usize,
    first: u64,
    last: u64,
}

/// A set of ground cells as a bitmap over the grid, storing only a window of rows.
///
/// Rows `stored_rows()` are stored, `words_per_row` words each; every other row holds no
/// cell and reads as zeros ([`CellSet::row`]). Adding a cell outside the window widens it
/// (with some slack, so rows added one at a time cost amortised constant time), and the
/// meets and differences forget the empty rows at its ends when they are many. So a set
/// that covers a camera's view or one car costs its rows, not the region's: every
/// operation between two sets visits the stored rows of the one that bounds the result.
/// The window is storage only: equality, digests and every query read the set as a bitmap
/// over the whole grid.
#[derive(Clone, Debug)]
pub struct CellSet {
    nx: u32,
    ny: u32,
    words_per_row: usize,
    /// The first stored row.
    first: u32,
    /// One past the last stored row (`first == end`: no row is stored).
    end: u32,
    /// The words of rows `first..end`, row after row.
    words: Vec<u64>,
}

/// The words [`CellSet::row`] hands out for a row that is not stored. A grid with wider rows
/// stores every row.
static ZERO_ROW: [u64; 1024] = [0; 1024];

/// The FNV-1a prime of [`CellSet::digest`] and [`CellSet::fingerprint`].
const FNV_PRIME: u64 = 0x100_0000_01b3;
/// The FNV-1a offset basis.
const FNV_BASIS: u64 = 0xcbf2_9ce4_8422_2325;

/// `FNV_PRIME^n` (wrapping): what `n` zero words do to an FNV-1a hash, `h ← (h ^ 0) · P`.
fn prime_power(mut n: u64) -> u64 {
    let (mut base, mut out) = (FNV_PRIME, 1u64);
    while n > 0 {
        if n & 1 == 1 {
            out = out.wrapping_mul(base);
        }
        base = base.wrapping_mul(base);
        n >>= 1;
    }
    out
}

/// The rows of either range (ranges with `start >= end` hold none).
fn union_rows(a: Range<u32>, b: Range<u32>) -> Range<u32> {
    match (a.is_empty(), b.is_empty()) {
        (true, _) => b,
        (_, true) => a,
        _ => a.start.min(b.start)..a.end.max(b.end),
    }
}

/// The rows of both ranges.
pub(crate) fn common_rows(a: Range<u32>, b: Range<u32>) -> Range<u32> {
    a.start.max(b.start)..a.end.min(b.end)
}

/// Cells equal as bitmaps over the whole grid, however many rows each stores.
impl PartialEq for CellSet {
    fn eq(&self, other: &Self) -> bool {
        self.same_shape(other)
            && union_rows(self.stored_rows(), other.stored_rows())
                .all(|iy| self.row(iy) == other.row(iy))
    }
}

impl Eq for CellSet {}

/// A compact, self-describing encoding of a [`CellSet`] for messages: the bounding box of the
/// set and run lengths of alternating empty/full cells inside it, row-major, starting with an
/// empty run.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct EncodedSet {
    /// Grid width the set was encoded on.
    pub nx: u32,
    /// Grid height the set was encoded on.
    pub ny: u32,
    /// Bounding box of the set; `None` for the empty set.
    pub bbox: Option<CellBox>,
    /// Alternating run lengths (empty first) covering the box row by row.
    pub runs: Vec<u32>,
}

/// Why an [`EncodedSet`] could not be decoded.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum SetDecodeError {
    /// The set was encoded on a grid of another size.
    #[error("set encoded on a {got_nx}x{got_ny} grid, expected {nx}x{ny}")]
    GridMismatch {
        /// Expected width.
        nx: u32,
        /// Expected height.
        ny: u32,
        /// Width in the message.
        got_nx: u32,
        /// Height in the message.
        got_ny: u32,
    },
    /// The bounding box is empty or reaches outside the grid.
    #[error("bounding box {0:?} is outside the grid")]
    BadBox(CellBox),
    /// The runs do not add up to the box's cell count.
    #[error("runs cover {got} cells, the box holds {expected}")]
    RunLength {
        /// Cells in the box.
        expected: u64,
        /// Cells the runs cover.
        got: u64,
    },
}

impl CellSet {
    /// The empty set on `grid`.
    pub fn empty(grid: &GroundGrid) -> Self {
        Self::empty_of_shape(grid.nx, grid.ny)
    }

    /// The empty set on a grid of `nx x ny` cells.
    fn empty_of_shape(nx: u32, ny: u32) -> Self {
        let mut set = Self {
            nx,
            ny,
            words_per_row: (nx as usize).div_ceil(64),
            first: 0,
            end: 0,
            words: Vec::new(),
        };
        if set.stores_every_row() {
            set.store_rows(0, ny);
        }
        set
    }

    /// The empty set on the grid of `self`.
    pub(crate) fn empty_like(&self) -> Self {
        Self::empty_of_shape(self.nx, self.ny)
    }

    /// The set of every cell of `grid`.
    pub fn full(grid: &GroundGrid) -> Self {
        let mut s = Self::empty(grid);
        s.fill_all();
        s
    }

    /// Adds every cell of the grid.
    fn fill_all(&mut self) {
        if self.nx == 0 {
            return;
        }
        self.store_rows(0, self.ny);
        for iy in 0..self.ny {
            self.fill_row_span(iy, 0, self.nx - 1);
        }
    }

    /// The set of the given cells of `grid`; cells outside the grid are ignored.
    pub fn from_cells(grid: &GroundGrid, cells: impl IntoIterator<Item = CellIndex>) -> Self {
        let mut s = Self::empty(grid);
        for c in cells {
            s.set(c, true);
        }
        s
    }

    /// Grid width in cells.
    pub fn nx(&self) -> u32 {
        self.nx
    }

    /// Grid height in cells.
    pub fn ny(&self) -> u32 {
        self.ny
    }

    /// Words per row.
    pub fn words_per_row(&self) -> usize {
        self.words_per_row
    }

    /// The rows the set stores: every row outside them holds no cell (rows inside may be
    /// empty too).
    pub fn stored_rows(&self) -> Range<u32> {
        self.first..self.end
    }

    /// Whether rows this wide are too wide for [`ZERO_ROW`], so that every row is stored.
    fn stores_every_row(&self) -> bool {
        self.words_per_row > ZERO_ROW.len()
    }

    /// Widens the stored rows to hold rows `lo..hi` (clamped to the grid); the new rows are
    /// empty. A window that grows takes a quarter of its rows more on the side it grows, so
    /// that a set filled row by row reallocates a logarithmic number of times.
    fn store_rows(&mut self, lo: u32, hi: u32) {
        let hi = hi.min(self.ny);
        if lo >= hi {
            return;
        }
        let wpr = self.words_per_row;
        if self.first >= self.end {
            self.words.clear();
            self.words.resize((hi - lo) as usize * wpr, 0);
            (self.first, self.end) = (lo, hi);
            return;
        }
        if lo >= self.first && hi <= self.end {
            return;
        }
        let slack = (self.end - self.first) / 4;
        let first = if lo < self.first {
            lo.saturating_sub(slack)
        } else {
            self.first
        };
        let end = if hi > self.end {
            hi.saturating_add(slack).min(self.ny)
        } else {
            self.end
        };
        let total = (end - first) as usize * wpr;
        if first < self.first {
            let mut words = Vec::with_capacity(total);
            words.resize((self.first - first) as usize * wpr, 0);
            words.extend_from_slice(&self.words);
            self.words = words;
        }
        self.words.resize(total, 0);
        (self.first, self.end) = (first, end);
    }

    /// Forgets the empty rows at the ends of the stored ones when they are more than half of
    /// them (and more than a few), and every row when the set is empty; the cells do not
    /// change. The meets and differences call it; so may any owner of a set that shrank.
    pub fn trim_rows(&mut self) {
        if self.stores_every_row() || self.first >= self.end {
            return;
        }
        let wpr = self.words_per_row.max(1);
        let Some(lead) = self.words.iter().position(|&w| w != 0) else {
            (self.first, self.end) = (0, 0);
            self.words = Vec::new();
            return;
        };
        let trail = self.words.iter().rposition(|&w| w != 0).unwrap_or(lead);
        let (top, bottom) = (lead / wpr, trail / wpr + 1);
        let rows = (self.end - self.first) as usize;
        let empty = top + (rows - bottom);
        if empty <= 8 || 2 * empty <= rows {
            return;
        }
        self.words.truncate(bottom * wpr);
        self.words.drain(..top * wpr);
        if self.words.capacity() > 2 * self.words.len() {
            self.words.shrink_to_fit();
        }
        self.first += top as u32;
        self.end = self.first + (bottom - top) as u32;
    }

    /// The words of rows `rows`, which must be stored, row after row.
    fn stored_slice(&self, rows: Range<u32>) -> &[u64] {
        let wpr = self.words_per_row;
        &self.words
            [(rows.start - self.first) as usize * wpr..(rows.end - self.first) as usize * wpr]
    }

    /// [`CellSet::stored_slice`], mutable.
    fn stored_slice_mut(&mut self, rows: Range<u32>) -> &mut [u64] {
        let wpr = self.words_per_row;
        &mut self.words
            [(rows.start - self.first) as usize * wpr..(rows.end - self.first) as usize * wpr]
    }

    /// The words of the stored rows among `rows`, row after row, and the first of those rows:
    /// the other rows of `rows` hold no cell.
    pub fn stored_words(&self, rows: Range<u32>) -> (u32, &[u64]) {
        let rows = common_rows(rows, self.stored_rows());
        if rows.is_empty() {
            return (rows.start, &[]);
        }
        (rows.start, self.stored_slice(rows))
    }

    /// The words of row `iy` (zeros for a row the set does not store).
    pub fn row(&self, iy: u32) -> &[u64] {
        if iy >= self.first && iy < self.end {
            let s = (iy - self.first) as usize * self.words_per_row;
            &self.words[s..s + self.words_per_row]
        } else {
            debug_assert!(iy < self.ny, "row {iy} outside a grid of {} rows", self.ny);
            &ZERO_ROW[..self.words_per_row]
        }
    }

    /// The words of row `iy`, mutable; the row is stored from then on. Bits past `nx` must
    /// stay clear. Panics for a row outside the grid.
    pub fn row_mut(&mut self, iy: u32) -> &mut [u64] {
        assert!(iy < self.ny, "row {iy} outside a grid of {} rows", self.ny);
        self.store_rows(iy, iy + 1);
        let s = (iy - self.first) as usize * self.words_per_row;
        &mut self.words[s..s + self.words_per_row]
    }

    /// Whether `other` lives on a grid of the same size.
    pub fn same_shape(&self, other: &CellSet) -> bool {
        self.nx == other.nx && self.ny == other.ny
    }

    /// Whether cell `(ix, iy)` is in the set (`false` outside the grid).
    pub fn contains(&self, (ix, iy): CellIndex) -> bool {
        if ix >= self.nx || iy >= self.ny {
            return false;
        }
        self.row(iy)[ix as usize / 64] >> (ix % 64) & 1 == 1
    }

    /// Adds or removes cell `(ix, iy)`; ignored outside the grid.
    pub fn set(&mut self, (ix, iy): CellIndex, value: bool) {
        if ix >= self.nx || iy >= self.ny || !(value || self.stored_rows().contains(&iy)) {
            return;
        }
        let w = &mut self.row_mut(iy)[ix as usize / 64];
        let bit = 1u64 << (ix % 64);
        if value {
            *w |= bit;
        } else {
            *w &= !bit;
        }
    }

    /// Adds cells `x0..=x1` of row `iy` (clamped to the grid).
    pub fn fill_row_span(&mut self, iy: u32, x0: u32, x1: u32) {
        let Some(span) = self.span_words(iy, x0, x1) else {
            return;
        };
        let row = self.row_mut(iy);
        if span.w0 == span.w1 {
            row[span.w0] |= span.first & span.last;
        } else {
            row[span.w0] |= span.first;
            row[span.w0 + 1..span.w1].fill(u64::MAX);
            row[span.w1] |= span.last;
        }
    }

    /// The words and end masks of columns `x0..=x1` of row `iy`, clamped to the grid; `None`
    /// for a row outside the grid or an empty span.
    fn span_words(&self, iy: u32, x0: u32, x1: u32) -> Option<SpanWords> {
        if iy >= self.ny || x0 > x1 || x0 >= self.nx {
            return None;
        }
        let x1 = x1.min(self.nx - 1);
        Some(SpanWords {
            w0: x0 as usize / 64,
            w1: x1 as usize / 64,
            first: u64::MAX << (x0 % 64),
            last: u64::MAX >> (63 - x1 % 64),
        })
    }

    /// Flips the cells of row `iy` in columns `x0..=x1` (clamped to the grid, as
    /// [`CellSet::fill_row_span`]).
    pub(crate) fn flip_row_span(&mut self, iy: u32, x0: u32, x1: u32) {
        let Some(span) = self.span_words(iy, x0, x1) else {
            return;
        };
        let row = self.row_mut(iy);
        if span.w0 == span.w1 {
            row[span.w0] ^= span.first & span.last;
        } else {
            row[span.w0] ^= span.first;
            row[span.w0 + 1..span.w1].iter_mut().for_each(|w| *w = !*w);
            row[span.w1] ^= span.last;
        }
    }

    /// Whether row `iy` holds every cell of columns `x0..=x1` (clamped to the grid; `false`
    /// for a row outside the grid or an empty span).
    pub fn row_span_is_full(&self, iy: u32, x0: u32, x1: u32) -> bool {
        if iy >= self.ny || x0 > x1 || x0 >= self.nx {
            return false;
        }
        let x1 = x1.min(self.nx - 1);
        let row = self.row(iy);
        let (w0, w1) = (x0 as usize / 64, x1 as usize / 64);
        (w0..=w1).all(|w| {
            let lo = if w == w0 { x0 % 64 } else { 0 };
            let hi = if w == w1 { x1 % 64 } else { 63 };
            let mask = (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
            row[w] & mask == mask
        })
    }

    /// Whether the set has no cell.
    pub fn is_empty(&self) -> bool {
        self.words.iter().all(|&w| w == 0)
    }

    /// Number of cells in the set.
    pub fn count(&self) -> u64 {
        self.words.iter().map(|w| w.count_ones() as u64).sum()
    }

    /// A 64-bit fingerprint of the set's cells (FNV-1a over the words of every row of the
    /// grid), to compare sets held by different processes without shipping them.
    pub fn digest(&self) -> u64 {
        let wpr = self.words_per_row as u64;
        let mut h = FNV_BASIS.wrapping_mul(prime_power(u64::from(self.first) * wpr));
        for &w in &self.words {
            h = (h ^ w).wrapping_mul(FNV_PRIME);
        }
        h.wrapping_mul(prime_power(
            u64::from(self.ny - self.end.max(self.first)) * wpr,
        ))
    }

    /// A 64-bit fingerprint of the set's cells for the wire ([`delta::SetDelta`]): FNV-1a
    /// over the words of every row of the grid in four interleaved lanes (word `i` in lane
    /// `i % 4`), folded together at the end. Its four independent multiplications per step
    /// run about four times as fast as [`CellSet::digest`]'s one chain, and it tells sets
    /// apart as well; it is another value.
    pub fn fingerprint(&self) -> u64 {
        let wpr = self.words_per_row as u64;
        let total = u64::from(self.ny) * wpr;
        let lead = u64::from(self.first) * wpr;
        let stored = self.words.len() as u64;
        let mut lanes = [FNV_BASIS, FNV_BASIS ^ 1, FNV_BASIS ^ 2, FNV_BASIS ^ 3];
        zero_words(&mut lanes, 0, lead);
        // The stored words start in lane `lead % 4`: turn the lanes so that lane 0 is it.
        let turn = (lead % 4) as usize;
        lanes.rotate_left(turn);
        let chunks = self.words.chunks_exact(4);
        let rest = chunks.remainder();
        for chunk in chunks {
            for (h, &w) in lanes.iter_mut().zip(chunk) {
                *h = (*h ^ w).wrapping_mul(FNV_PRIME);
            }
        }
        for (h, &w) in lanes.iter_mut().zip(rest) {
            *h = (*h ^ w).wrapping_mul(FNV_PRIME);
        }
        lanes.rotate_right(turn);
        zero_words(&mut lanes, lead + stored, total - lead - stored);
        let folded = lanes
            .iter()
            .fold(FNV_BASIS, |h, &lane| (h ^ lane).wrapping_mul(FNV_PRIME));
        (folded ^ total).wrapping_mul(FNV_PRIME)
    }

    /// Area of the set, m² (an upper bound of the true set's area for outer sets).
    pub fn area(&self, grid: &GroundGrid) -> Real {
        self.count() as Real * grid.cell_area()
    }

    /// `self ← self ∩ other`. Both sets must share the grid.
    pub fn and_assign(&mut self, other: &CellSet) {
        debug_assert!(self.same_shape(other));
        let wpr = self.words_per_row.max(1);
        let first = self.first;
        for (iy, row) in (first..).zip(self.words.chunks_exact_mut(wpr)) {
            for (a, b) in row.iter_mut().zip(other.row(iy)) {
                *a &= b;
            }
        }
        self.trim_rows();
    }

    /// `self ← self ∪ other`. Both sets must share the grid.
    pub fn or_assign(&mut self, other: &CellSet) {
        self.or_assign_within(other, 0..self.ny);
    }

    /// `self ← self ∪ (other ∩ rows)`: the cells of `other` in rows `rows` join the set, at
    /// the cost of those rows. Both sets must share the grid.
    pub fn or_assign_within(&mut self, other: &CellSet, rows: Range<u32>) {
        debug_assert!(self.same_shape(other));
        let Some((lo, hi)) = other.row_range_within(rows) else {
            return;
        };
        let rows = lo..hi + 1;
        self.store_rows(rows.start, rows.end);
        let theirs = other.stored_slice(rows.clone());
        for (a, b) in self.stored_slice_mut(rows).iter_mut().zip(theirs) {
            *a |= b;
        }
    }

    /// `self ← self \ other`. Both sets must share the grid.
    pub fn and_not_assign(&mut self, other: &CellSet) {
        debug_assert!(self.same_shape(other));
        let rows = common_rows(self.stored_rows(), other.stored_rows());
        if rows.is_empty() {
            return;
        }
        let theirs = other.stored_slice(rows.clone());
        for (a, b) in self.stored_slice_mut(rows).iter_mut().zip(theirs) {
            *a &= !b;
        }
        self.trim_rows();
    }

    /// The words of both sets over the rows both store, side by side.
    fn common_words<'a>(&'a self, other: &'a CellSet) -> impl Iterator<Item = (u64, u64)> + 'a {
        let rows = common_rows(self.stored_rows(), other.stored_rows());
        let (mine, theirs): (&[u64], &[u64]) = if rows.is_empty() {
            (&[], &[])
        } else {
            (self.stored_slice(rows.clone()), other.stored_slice(rows))
        };
        mine.iter().copied().zip(theirs.iter().copied())
    }

    /// Number of cells in `self ∩ other`, without building it.
    pub fn intersection_count(&self, other: &CellSet) -> u64 {
        self.common_words(other)
            .map(|(a, b)| (a & b).count_ones() as u64)
            .sum()
    }

    /// Whether every cell of `self` is in `other`.
    pub fn is_subset_of(&self, other: &CellSet) -> bool {
        debug_assert!(self.same_shape(other));
        self.stored_rows().all(|iy| {
            self.row(iy)
                .iter()
                .zip(other.row(iy))
                .all(|(a, b)| a & !b == 0)
        })
    }

    /// Whether `self` and `other` share a cell.
    pub fn intersects(&self, other: &CellSet) -> bool {
        debug_assert!(self.same_shape(other));
        self.common_words(other).any(|(a, b)| a & b != 0)
    }

    /// Number of cells of `self \ other`, without building it.
    pub fn difference_count(&self, other: &CellSet) -> u64 {
        debug_assert!(self.same_shape(other));
        self.stored_rows()
            .map(|iy| {
                self.row(iy)
                    .iter()
                    .zip(other.row(iy))
                    .map(|(a, b)| (a & !b).count_ones() as u64)
                    .sum::<u64>()
            })
            .sum()
    }

    /// Whether row `iy` holds no cell (`true` outside the grid).
    pub fn row_is_empty(&self, iy: u32) -> bool {
        iy >= self.ny || self.row(iy).iter().all(|&w| w == 0)
    }

    /// The first and last non-empty rows, `None` when the set is empty.
    pub fn row_range(&self) -> Option<(u32, u32)> {
        self.row_range_within(0..self.ny)
    }

    /// The first and last non-empty rows among `rows`, `None` when they hold no cell.
    pub fn row_range_within(&self, rows: Range<u32>) -> Option<(u32, u32)> {
        let (start, words) = self.stored_words(rows);
        let wpr = self.words_per_row.max(1);
        let first = words.iter().position(|&w| w != 0)?;
        let last = words.iter().rposition(|&w| w != 0)?;
        Some((start + (first / wpr) as u32, start + (last / wpr) as u32))
    }

    /// Iterates over the cells of the set, row by row.
    pub fn iter(&self) -> impl Iterator<Item = CellIndex> + '_ {
        self.stored_rows().flat_map(move |iy| {
            self.row(iy).iter().enumerate().flat_map(move |(w, &word)| {
                let mut bits = word;
                std::iter::from_fn(move || {
                    if bits == 0 {
                        return None;
                    }
                    let b = bits.trailing_zeros();
                    bits &= bits - 1;
                    Some((w as u32 * 64 + b, iy))
                })
            })
        })
    }
}

/// What `n` zero words from word `start` on (of the whole grid) do to the lanes of
/// [`CellSet::fingerprint`]: word `i` multiplies lane `i % 4` by the prime.
fn zero_words(lanes: &mut [u64; 4], start: u64, n: u64) {
    // Words `0..x` in lane `l`: those `i < x` with `i % 4 == l`.
    let in_lane = |x: u64, l: u64| (x + 3 - l) / 4;
    for (l, lane) in (0u64..).zip(lanes.iter_mut()) {
        *lane = lane.wrapping_mul(prime_power(in_lane(start + n, l) - in_lane(start, l)));
    }
}
