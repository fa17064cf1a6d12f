//! Conservative disc dilation on cell distance (docs/design.md §3).
//!
//! Cell `(x + dx, y + dy)` joins when the closed squares of the two cells are within the
//! radius: `cell_m * hypot(max(|dx| - 1, 0), max(|dy| - 1, 0)) <= radius` (plus a margin).
//! The element is a union of horizontal runs, one per row offset `dy` with half-width
//! `rx(|dy|)`, and `rx` shrinks as `|dy|` grows. So each non-empty source row is smeared
//! horizontally, word-parallel, from the narrowest run (largest `|dy|`) to the widest, and
//! each stage is OR-ed into rows `y - dy` and `y + dy`.

use std::ops::Range;

use super::{CellSet, margin};
use crate::grid::GroundGrid;
use crate::math::Real;

impl CellSet {
    /// Conservative dilation by a disc of `radius` metres: cell `(x+dx, y+dy)` joins when the
    /// closed squares of the two cells are within `radius` of each other (up to a margin of
    /// about `1e-9` relative that only ever adds cells), so the result contains every point
    /// within `radius` of the set. Only `grid.cell_m` is read from `grid`; the result has the
    /// shape of `self`.
    ///
    /// Radius 0 still adds the 8 neighbours: their closed squares touch the set's. A negative
    /// radius returns the set unchanged; a NaN or infinite radius (or a grid without a
    /// positive finite cell size) returns the whole grid when the set is not empty, the only
    /// safe answer.
    pub fn dilate(&self, grid: &GroundGrid, radius: Real) -> CellSet {
        if radius < 0.0 || self.is_empty() {
            return self.clone();
        }
        let d = grid.cell_m;
        let reach = (radius + margin(radius + d)) / d;
        if !(reach.is_finite() && d > 0.0) {
            let mut all = self.empty_like();
            all.fill_all();
            return all;
        }
        let run = row_runs(reach, self.nx, self.ny);
        let Some((lo, hi)) = self.row_range() else {
            return self.clone();
        };
        let k_max = run.len() - 1;
        let mut out = self.empty_like();
        out.store_rows(
            lo.saturating_sub(k_max as u32),
            hi.saturating_add(k_max as u32 + 1),
        );
        let wpr = self.words_per_row;
        let widest = run[0] as usize;
        // Padding on both sides keeps every bit within `widest` of the row in the buffer,
        // so the smearing never loses a bit it will need.
        let pad = widest.div_ceil(64) + 1;
        let mut smear = vec![0u64; wpr + 2 * pad];
        let mut scratch = vec![0u64; wpr + 2 * pad];
        for y in lo..=hi {
            let src = self.row(y);
            if src.iter().all(|&w| w == 0) {
                continue;
            }
            smear.fill(0);
            smear[pad..pad + wpr].copy_from_slice(src);
            let mut half_width = 0;
            for k in (0..=k_max).rev() {
                widen(&mut smear, &mut scratch, run[k] - half_width);
                half_width = run[k];
                let stage = &smear[pad..pad + wpr];
                let (k, y) = (k as u64, u64::from(y));
                if let Some(up) = y.checked_add(k).filter(|&t| t < u64::from(self.ny)) {
                    or_into(out.row_mut(up as u32), stage);
                }
                if let Some(down) = y.checked_sub(k).filter(|_| k > 0) {
                    or_into(out.row_mut(down as u32), stage);
                }
            }
        }
        out.clear_tails();
        out
    }

    /// The disc element of [`CellSet::dilate`] by `radius` metres, for reading single words
    /// of a dilation without building it ([`WordDilation::word`]).
    pub fn word_dilation(&self, grid: &GroundGrid, radius: Real) -> WordDilation {
        self.word_dilation_within(grid, radius, 0..self.ny)
    }

    /// [`CellSet::word_dilation`] of a set whose cells all lie in rows `rows`: the same
    /// words, found by reading only those rows (a small set on a large grid pays for its
    /// rows). Rows of the set outside `rows` would be ignored.
    pub fn word_dilation_within(
        &self,
        grid: &GroundGrid,
        radius: Real,
        rows: Range<u32>,
    ) -> WordDilation {
        let rows = rows.start.min(self.ny)..rows.end.min(self.ny);
        let d = grid.cell_m;
        let reach = (radius + margin(radius + d)) / d;
        let empty = self.row_range_within(rows.clone()).is_none();
        let element = if radius < 0.0 || empty {
            Element::Identity
        } else if !(reach.is_finite() && d > 0.0) {
            Element::Everything
        } else {
            Element::Runs(row_runs(reach, self.nx, self.ny))
        };
        // Bits of a source row more than the widest run away from a word cannot reach it.
        let pad = match &element {
            Element::Runs(run) => (run[0] as usize).div_ceil(64),
            _ => 0,
        };
        let support = match &element {
            // `word` reads rows `iy ± (run.len() - 1)` and words `w ± max(pad, 1)`.
            Element::Runs(run) => Some(self.word_support(rows, run.len() - 1, pad.max(1))),
            Element::Identity => Some(self.word_support(rows, 0, 0)),
            Element::Everything => None,
        };
        WordDilation {
            element,
            pad,
            buffer: vec![0; 2 * pad + 1],
            scratch: vec![0; 2 * pad + 1],
            support,
        }
    }

    /// Per row, one bit per word: set when a word of the set within `rows` rows and `words`
    /// words of it (on the grid) is not empty; the set's cells lie in rows `held`.
    fn word_support(&self, held: Range<u32>, rows: usize, words: usize) -> WordMask {
        let (ny, wpr) = (self.ny as usize, self.words_per_row);
        let per_row = wpr.div_ceil(64).max(1);
        let held = held.start as usize..held.end as usize;
        // The rows' non-empty words, grown by `words` along the row.
        let mut across = vec![0u64; ny * per_row];
        let mut shifted = vec![0u64; per_row];
        let (first, stored) = self.stored_words(held.start as u32..held.end as u32);
        let first = first as usize;
        for (row, mask) in stored
            .chunks_exact(wpr.max(1))
            .zip(across[first * per_row..].chunks_exact_mut(per_row))
        {
            for (w, &word) in row.iter().enumerate() {
                mask[w / 64] |= u64::from(word != 0) << (w % 64);
            }
            for _ in 0..words {
                shifted.copy_from_slice(mask);
                for i in 0..per_row {
                    let carry_up = if i > 0 { shifted[i - 1] >> 63 } else { 0 };
                    let carry_down = shifted.get(i + 1).map_or(0, |h| h << 63);
                    mask[i] |= shifted[i] << 1 | carry_up | shifted[i] >> 1 | carry_down;
                }
            }
        }
        // Then by `rows` across the rows (only rows near `held` can gain a bit).
        let mut bits = vec![0u64; ny * per_row];
        let near = held.start.saturating_sub(rows)..(held.end + rows).min(ny);
        for (iy, out) in bits
            .chunks_exact_mut(per_row)
            .enumerate()
            .take(near.end)
            .skip(near.start)
        {
            let (a, b) = (iy.saturating_sub(rows), (iy + rows).min(ny - 1));
            for src in across[a * per_row..(b + 1) * per_row].chunks_exact(per_row) {
                for (o, s) in out.iter_mut().zip(src) {
                    *o |= s;
                }
            }
        }
        WordMask { per_row, bits }
    }

    /// Clears the bits past `nx` in the last word of every row.
    fn clear_tails(&mut self) {
        let used = self.nx % 64;
        if used == 0 || self.words_per_row == 0 {
            return;
        }
        let mask = (1u64 << used) - 1;
        let wpr = self.words_per_row;
        for row in self.words.chunks_exact_mut(wpr) {
            row[wpr - 1] &= mask;
        }
    }
}

/// One word at a time of the dilation of a set by a disc ([`CellSet::word_dilation`]): what
/// [`CellSet::dilate`] would put in that word, computed from the rows and words within the
/// disc's reach only, so that a caller who needs a few words of a dilation of a large set
/// does not pay for the whole grid. It keeps its scratch buffers between words.
#[derive(Clone, Debug)]
pub struct WordDilation {
    element: Element,
    /// Words on each side of the word read: the reach of the widest run, plus one.
    pad: usize,
    buffer: Vec<u64>,
    scratch: Vec<u64>,
    /// The words of the dilation that may hold cells (`None`: every word).
    support: Option<WordMask>,
}

/// One bit per word of a [`CellSet`], row by row.
#[derive(Clone, Debug)]
struct WordMask {
    per_row: usize,
    bits: Vec<u64>,
}

impl WordMask {
    fn contains(&self, iy: u32, w: usize) -> bool {
        let i = iy as usize * self.per_row + w / 64;
        self.bits.get(i).is_some_and(|b| b >> (w % 64) & 1 != 0)
    }

    fn row_has_any(&self, iy: u32) -> bool {
        let start = iy as usize * self.per_row;
        self.bits
            .get(start..start + self.per_row)
            .is_some_and(|row| row.iter().any(|&b| b != 0))
    }
}

#[derive(Clone, Debug)]
enum Element {
    /// A negative radius or an empty set: the set itself.
    Identity,
    /// A radius no cell size bounds, around a non-empty set: the whole grid.
    Everything,
    /// Half-widths by row offset ([`row_runs`]).
    Runs(Vec<u32>),
}

impl WordDilation {
    /// False when word `w` of row `iy` of the dilation is certainly empty: no cell of the set
    /// it was made from lies within the element's reach of the word. True otherwise (the
    /// word may still be empty).
    pub fn may_hold(&self, iy: u32, w: usize) -> bool {
        self.support.as_ref().is_none_or(|s| s.contains(iy, w))
    }

    /// False when row `iy` of the dilation is certainly empty ([`WordDilation::may_hold`] of
    /// each of its words is false).
    pub fn may_hold_row(&self, iy: u32) -> bool {
        self.support.as_ref().is_none_or(|s| s.row_has_any(iy))
    }

    /// Word `w` of row `iy` of `set.dilate(grid, radius)`, for the `grid` and `radius` this
    /// was made with and the `set` it was made from, unchanged since (row and word inside it).
    pub fn word(&mut self, set: &CellSet, iy: u32, w: usize) -> u64 {
        let tail = tail_mask(set, w);
        let run = match &self.element {
            Element::Identity => return set.row(iy)[w],
            Element::Everything => return tail,
            Element::Runs(run) => run,
        };
        let pad = self.pad;
        let wpr = set.words_per_row;
        let mut out = 0;
        for (k, &half_width) in run.iter().enumerate() {
            let k = k as u32;
            let up = iy.checked_add(k).filter(|&t| t < set.ny);
            let down = iy.checked_sub(k).filter(|_| k > 0);
            for y in [up, down].into_iter().flatten() {
                let row = set.row(y);
                if pad <= 1 {
                    // Runs of at most one word: shift the word and its two neighbours.
                    let lo = w.checked_sub(1).map_or(0, |i| row[i]);
                    let hi = row.get(w + 1).copied().unwrap_or(0);
                    out |= smear_word(lo, row[w], hi, half_width);
                    continue;
                }
                // The words `w - pad ..= w + pad` of the source row, 0 past its ends.
                let mut any = false;
                for (j, slot) in self.buffer.iter_mut().enumerate() {
                    let src = (w + j).checked_sub(pad).filter(|&i| i < wpr);
                    *slot = src.map_or(0, |i| row[i]);
                    any |= *slot != 0;
                }
                if any {
                    widen(&mut self.buffer, &mut self.scratch, half_width);
                    out |= self.buffer[pad];
                }
            }
        }
        out & tail
    }
}

/// The middle word of the three words `lo, mid, hi` (in increasing bit order) after every run
/// of set bits grew by `by <= 64` on both sides.
fn smear_word(lo: u64, mid: u64, hi: u64, by: u32) -> u64 {
    if lo | mid | hi == 0 {
        return 0;
    }
    let mut out = mid;
    for s in 1..=by.min(63) {
        out |= mid << s | lo >> (64 - s) | mid >> s | hi << (64 - s);
    }
    if by >= 64 {
        out |= lo | hi;
    }
    out
}

/// The bits of word `w` of a row that lie on the grid.
fn tail_mask(set: &CellSet, w: usize) -> u64 {
    let used = set.nx as usize - (w * 64).min(set.nx as usize);
    if used >= 64 {
        u64::MAX
    } else {
        (1u64 << used) - 1
    }
}

/// Half-widths of the structuring element by row offset: `run[k]` is the largest `dx` with
/// `max(dx - 1, 0)² + max(k - 1, 0)² <= reach²` (in cells), capped at the grid width; the
/// offsets stop where no cell joins or at the grid height.
fn row_runs(reach: Real, nx: u32, ny: u32) -> Vec<u32> {
    let k_max = (reach.floor() + 1.0).min(Real::from(ny)) as u32;
    let r2 = reach * reach;
    (0..=k_max)
        .map(|k| {
            let a = Real::from(k.saturating_sub(1));
            let guess = ((reach - a) * (reach + a)).max(0.0).sqrt().floor();
            if guess >= Real::from(nx) {
                return nx;
            }
            // Settle the estimate on the defining inequality.
            let mut b = guess as u32;
            let fits = |b: u32| Real::from(b) * Real::from(b) + a * a <= r2;
            while b < nx && fits(b + 1) {
                b += 1;
            }
            while b > 0 && !fits(b) {
                b -= 1;
            }
            (b + 1).min(nx)
        })
        .collect()
}

/// Grows every run of set bits of `bits` by `by` on both sides, using `scratch` (same length).
/// Each pass ORs the buffer shifted by `±k` with `k` up to `2w + 1` for a current half-width
/// `w`, so the half-width triples per pass.
fn widen(bits: &mut [u64], scratch: &mut [u64], by: u32) {
    let mut w = 0u32;
    while w < by {
        let k = (2 * w + 1).min(by - w);
        scratch.copy_from_slice(bits);
        or_shifted(bits, scratch, k as usize);
        w += k;
    }
}

/// `dst |= (src << k) | (src >> k)` on a little-endian bit vector (bit `i` is bit `i % 64` of
/// word `i / 64`); bits shifted past either end are dropped.
fn or_shifted(dst: &mut [u64], src: &[u64], k: usize) {
    let n = src.len();
    let (q, r) = (k / 64, (k % 64) as u32);
    for (i, out) in dst.iter_mut().enumerate() {
        let mut acc = 0u64;
        // Towards higher indices: bit j moves to j + k.
        if i >= q {
            acc |= src[i - q] << r;
            if r > 0 && i > q {
                acc |= src[i - q - 1] >> (64 - r);
            }
        }
        // Towards lower indices: bit j moves to j - k.
        if i + q < n {
            acc |= src[i + q] >> r;
            if r > 0 && i + q + 1 < n {
                acc |= src[i + q + 1] << (64 - r);
            }
        }
        *out |= acc;
    }
}

fn or_into(dst: &mut [u64], src: &[u64]) {
    dst.iter_mut().zip(src).for_each(|(a, b)| *a |= b);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::CellIndex;

    fn grid() -> GroundGrid {
        GroundGrid::new(50.0, 1.0)
    }

    #[test]
    fn the_words_a_dilation_may_hold_cross_the_mask_words_of_a_wide_grid() {
        // 130 words a row: the mask of a row spans three u64.
        let g = GroundGrid {
            origin: crate::math::Point2::origin(),
            cell_m: 1.0,
            nx: 64 * 130,
            ny: 9,
        };
        let set = CellSet::from_cells(&g, [(63 * 64, 4), (128 * 64 + 5, 4)]);
        let words = set.word_dilation(&g, 1.0);
        let whole = set.dilate(&g, 1.0);
        for iy in 0..g.ny {
            for w in 0..set.words_per_row() {
                let near = (62..=64).contains(&w) || (127..=129).contains(&w);
                let rows = (2..=6).contains(&iy);
                assert_eq!(words.may_hold(iy, w), near && rows, "row {iy} word {w}");
                assert!(whole.row(iy)[w] == 0 || words.may_hold(iy, w));
            }
        }
    }

    /// The dilation straight from its definition.
    fn brute(set: &CellSet, cell_m: Real, radius: Real) -> CellSet {
        let mut out = set.clone();
        let cells: Vec<CellIndex> = set.iter().collect();
        for iy in 0..set.ny() {
            for ix in 0..set.nx() {
                let near = cells.iter().any(|&(x, y)| {
                    let dx = (i64::from(ix) - i64::from(x)).abs();
                    let dy = (i64::from(iy) - i64::from(y)).abs();
                    let gx = (dx - 1).max(0) as Real;
                    let gy = (dy - 1).max(0) as Real;
                    cell_m * gx.hypot(gy) <= radius + 1e-9
                });
                if near {
                    out.set((ix, iy), true);
                }
            }
        }
        out
    }

    #[test]
    fn radius_zero_adds_the_touching_neighbours() {
        let g = grid();
        let s = CellSet::from_cells(&g, [(10, 10)]);
        let d = s.dilate(&g, 0.0);
        assert_eq!(d.count(), 9);
        assert!(d.contains((9, 9)) && d.contains((11, 11)));
    }

    #[test]
    fn matches_the_definition_across_word_boundaries_and_grid_edges() {
        let g = grid();
        let s = CellSet::from_cells(
            &g,
            [(0, 0), (63, 5), (64, 40), (99, 99), (50, 50), (51, 50)],
        );
        for radius in [0.0, 0.5, 1.0, 1.5, 2.0, 3.7, 6.0, 20.0, 70.0] {
            assert_eq!(
                s.dilate(&g, radius),
                brute(&s, 1.0, radius),
                "radius {radius}"
            );
        }
    }

    #[test]
    fn exact_reach_is_included() {
        // Squares 3 cells apart along x have a 2-cell gap: within 2.0, not within 1.99.
        let g = grid();
        let s = CellSet::from_cells(&g, [(20, 20)]);
        assert!(s.dilate(&g, 2.0).contains((23, 20)));
        assert!(!s.dilate(&g, 1.99).contains((23, 20)));
        // Diagonal gap of (1, 1) cells: sqrt(2).
        assert!(s.dilate(&g, 2.0_f64.sqrt()).contains((22, 22)));
        assert!(!s.dilate(&g, 1.41).contains((22, 22)));
    }

    #[test]
    fn invalid_radii_are_handled_safely() {
        let g = grid();
        let s = CellSet::from_cells(&g, [(3, 3)]);
        assert_eq!(s.dilate(&g, -1.0), s);
        assert_eq!(s.dilate(&g, Real::NAN).count(), 100 * 100);
        assert_eq!(s.dilate(&g, Real::INFINITY).count(), 100 * 100);
        assert_eq!(s.dilate(&g, 1e6).count(), 100 * 100);
        let empty = CellSet::empty(&g);
        assert!(empty.dilate(&g, Real::NAN).is_empty());
    }

    #[test]
    fn tails_past_the_grid_width_stay_clear() {
        let g = GroundGrid::new(35.0, 1.0); // 70 columns: the second word is partly used.
        let s = CellSet::from_cells(&g, [(69, 3)]);
        let d = s.dilate(&g, 5.0);
        assert!(d.row(3)[1] >> 6 == 0);
        assert_eq!(d, brute(&s, 1.0, 5.0));
    }
}
