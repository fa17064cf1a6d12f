//! What a set left alone becomes: the growth the `setfleet` planner charges on its predicted
//! sets.
//!
//! A set of possible positions left unobserved grows at the targets' speed `v` from its whole
//! boundary. In `G` seconds (`guidance.growth_horizon_s`) it becomes the set grown by `v G`.
//! The planner values a predicted set by the area of that grown set: on its planning grid,
//! the set grown by `r = round(v G / cell)` 8-neighbour rings (each cell's square of side
//! `2 r + 1` cells, the rings the planner grows its predictions by). [`Growth`] counts it.
//!
//! ## Why the grown set and not the boundary
//! The boundary's length `L` times `v G` is the growth of a long straight boundary. In a dense
//! city, the pockets a view leaves in the shadows of buildings lie closer than `v G` to each
//! other, and their growths overlap: the ground between them is regrown once, not once per
//! pocket. Counting `L v G` charged a view that cleared ground between shadows more for the
//! pockets' boundaries than it cleared, so seeing ground could make a sequence's value worse.
//! The grown set cannot: it is monotone (a subset grows into a subset), so removing cells
//! from a set never makes its value larger, and a pocket cleared whole still removes all of
//! its growth, the property the boundary charge was there for. On a straight boundary of `L`
//! cells both count `r L` cells.
//!
//! ## Cost
//! A beam node's sets are grown once per period ([`Growth::of`]: each row widened by `r` bits,
//! then each row ORed with the `r` rows either side with van Herk and Gil-Werman's running
//! maximum, three word operations per word whatever `r`), and each child, whose views change
//! rows `a..=b` only, is counted again on the rows those can reach
//! ([`Growth::grown_cells_after`]): rows `a..=b` widened again, and the grown rows
//! `a - r..=b + r` recomputed.

use sets::grid::GroundGrid;
use sets::raster::CellSet;

use super::GuidanceParams;

/// The rings the `setfleet` planner's sets grow by over its growth horizon on `grid`: the
/// targets' reach in `guidance.growth_horizon_s` seconds, in whole rings (rounded).
pub fn horizon_rings(params: &GuidanceParams, grid: &GroundGrid) -> u32 {
    let reach_m = params.target_max_speed * params.setfleet.growth_horizon_s;
    rings(reach_m, grid.cell_m, grid.nx.max(grid.ny))
}

/// The rings of planning cells `cell_m` wide a set grows by in reaching `reach_m` metres:
/// `reach_m / cell_m` rounded (0 for a reach that is not positive), at most `limit` (a set
/// grown by the grid's size fills it).
fn rings(reach_m: f64, cell_m: f64, limit: u32) -> u32 {
    let r = (reach_m / cell_m).round();
    if r.is_nan() || r <= 0.0 {
        0
    } else {
        r.min(f64::from(limit)) as u32
    }
}

/// A set grown by `r` rings, kept row by row so that a set differing from it on a few rows is
/// counted on those rows' reach only.
#[derive(Clone, Debug)]
pub struct Growth {
    rings: u32,
    words_per_row: usize,
    /// Each row of the set widened by `rings` cells (its cells' horizontal reach).
    widened: Vec<u64>,
    /// Per row, the cells of the grown set.
    counts: Vec<u32>,
    /// The grown set's cells.
    total: u64,
}

impl Growth {
    /// `set` grown by `rings` rings (8-neighbour; cells past the grid's edges are not added).
    /// More rings than the grid is wide or long grow no further.
    pub fn of(set: &CellSet, rings: u32) -> Growth {
        let wpr = set.words_per_row();
        let ny = set.ny();
        let rings = rings.min(set.nx().max(ny));
        if rings == 0 {
            // Nothing grows: the rows' own counts, and no rows to keep.
            let counts: Vec<u32> = (0..ny).map(|y| row_count(set.row(y))).collect();
            return Growth {
                rings,
                words_per_row: wpr,
                widened: Vec::new(),
                total: counts.iter().map(|&c| u64::from(c)).sum(),
                counts,
            };
        }
        let mut widened = vec![0u64; wpr * ny as usize];
        let mut scratch = vec![0u64; wpr];
        let mask = tail_mask(set.nx());
        for y in 0..ny {
            let out = &mut widened[y as usize * wpr..(y as usize + 1) * wpr];
            widen(set.row(y), rings, mask, out, &mut scratch);
        }
        let mut counts = vec![0u32; ny as usize];
        let rows = |j: u32| &widened[j as usize * wpr..(j as usize + 1) * wpr];
        if ny > 0 {
            grown_counts(rows, wpr, rings, (0, ny - 1), (0, ny - 1), &mut counts);
        }
        let total = counts.iter().map(|&c| u64::from(c)).sum();
        Growth {
            rings,
            words_per_row: wpr,
            widened,
            counts,
            total,
        }
    }

    /// Cells of the grown set.
    pub fn grown_cells(&self) -> u64 {
        self.total
    }

    /// Cells of `after` grown the same way, where `after` differs from the set this was made
    /// of only on the rows `changed` (`None`: nowhere).
    pub fn grown_cells_after(&self, after: &CellSet, changed: Option<(u32, u32)>) -> u64 {
        let ny = self.counts.len() as u32;
        let Some((a, b)) = changed.filter(|&(a, b)| a <= b && a < ny) else {
            return self.total;
        };
        let b = b.min(ny - 1);
        let (wpr, r) = (self.words_per_row, self.rings);
        if r == 0 {
            let before: u64 = (a..=b).map(|y| u64::from(self.counts[y as usize])).sum();
            let after: u64 = (a..=b).map(|y| u64::from(row_count(after.row(y)))).sum();
            return self.total - before + after;
        }
        // The grown rows the change reaches, and the rows those are grown from.
        let out = (a.saturating_sub(r), b.saturating_add(r).min(ny - 1));
        let input = (a.saturating_sub(2 * r), b.saturating_add(2 * r).min(ny - 1));
        let mut rewidened = vec![0u64; wpr * (b - a + 1) as usize];
        let mut scratch = vec![0u64; wpr];
        let mask = tail_mask(after.nx());
        for y in a..=b {
            let i = (y - a) as usize;
            widen(
                after.row(y),
                r,
                mask,
                &mut rewidened[i * wpr..(i + 1) * wpr],
                &mut scratch,
            );
        }
        let rows = |j: u32| {
            if (a..=b).contains(&j) {
                let i = (j - a) as usize;
                &rewidened[i * wpr..(i + 1) * wpr]
            } else {
                &self.widened[j as usize * wpr..(j as usize + 1) * wpr]
            }
        };
        let mut counts = vec![0u32; (out.1 - out.0 + 1) as usize];
        grown_counts(rows, wpr, r, input, out, &mut counts);
        let before: u64 = self.counts[out.0 as usize..=out.1 as usize]
            .iter()
            .map(|&c| u64::from(c))
            .sum();
        let after: u64 = counts.iter().map(|&c| u64::from(c)).sum();
        self.total - before + after
    }
}

/// The cells of a row.
fn row_count(row: &[u64]) -> u32 {
    row.iter().map(|w| w.count_ones()).sum()
}

/// The bits of a row's last word that hold cells of a grid `nx` cells wide.
fn tail_mask(nx: u32) -> u64 {
    match nx % 64 {
        0 => u64::MAX,
        used => (1u64 << used) - 1,
    }
}

/// `out` = `row` with every cell widened by `r` cells either way, within the row (`mask`: the
/// last word's bits inside the grid). Each way by doubling: a row smeared `k` cells towards
/// higher `x` and then by `s <= k + 1` more is smeared `k + s`, so `r` takes about `log₂ r`
/// passes. (The two ways are smeared apart: a smear cut short by the grid's edge would leave
/// a gap in the other way's next pass.)
fn widen(row: &[u64], r: u32, mask: u64, out: &mut [u64], scratch: &mut [u64]) {
    out.copy_from_slice(row);
    if r == 0 || row.iter().all(|&w| w == 0) {
        return;
    }
    for towards_higher in [true, false] {
        scratch.copy_from_slice(row);
        let mut reach = 0u32;
        while reach < r {
            let s = (reach + 1).min(r - reach);
            smear(scratch, s, towards_higher);
            reach += s;
        }
        for (o, &w) in out.iter_mut().zip(scratch.iter()) {
            *o |= w;
        }
    }
    if let Some(last) = out.last_mut() {
        *last &= mask;
    }
}

/// `row[x] |= row[x - s]` (`towards_higher`) or `row[x] |= row[x + s]` for every cell `x` of
/// the row, at once (words of 64 cells, cell `x` at bit `x % 64` of word `x / 64`).
fn smear(row: &mut [u64], s: u32, towards_higher: bool) {
    let n = row.len();
    let (q, b) = ((s / 64) as usize, s % 64);
    let shifted = |row: &[u64], w: usize| -> u64 {
        let word = |i: Option<usize>| i.and_then(|i| row.get(i)).copied().unwrap_or(0);
        if towards_higher {
            let src = w.checked_sub(q);
            match b {
                0 => word(src),
                _ => (word(src) << b) | (word(src.and_then(|i| i.checked_sub(1))) >> (64 - b)),
            }
        } else {
            let src = Some(w + q).filter(|&i| i < n);
            match b {
                0 => word(src),
                _ => (word(src) >> b) | (word(src.map(|i| i + 1)) << (64 - b)),
            }
        }
    };
    // Walk against the shift's direction so every word reads its sources before they change.
    if towards_higher {
        for w in (0..n).rev() {
            let v = shifted(row, w);
            row[w] |= v;
        }
    } else {
        for w in 0..n {
            let v = shifted(row, w);
            row[w] |= v;
        }
    }
}

/// For every grown row `y` of `out` (inclusive), the cells of the OR of the widened rows
/// `y - r..=y + r` that lie in `input` (inclusive; the caller's rows, which must hold every
/// grid row within `r` of `out`), written to `counts[y - out.0]`. Van Herk / Gil-Werman: over
/// the rows padded with `r` empty rows either side, blocks of `2 r + 1` rows with each row's
/// OR from its block's start (`from_start`) and to its block's end (`to_end`); a window of
/// `2 r + 1` rows starting at `k` is `to_end[k] | from_start[k + 2 r]`.
fn grown_counts<'a>(
    rows: impl Fn(u32) -> &'a [u64],
    wpr: usize,
    r: u32,
    input: (u32, u32),
    out: (u32, u32),
    counts: &mut [u32],
) {
    let r_us = r as usize;
    let n = (input.1 - input.0 + 1) as usize;
    let padded = n + 2 * r_us;
    let block = 2 * r_us + 1;
    let mut from_start = vec![0u64; padded * wpr];
    let mut to_end = vec![0u64; padded * wpr];
    let at = |p: usize| -> Option<&'a [u64]> {
        (r_us..r_us + n)
            .contains(&p)
            .then(|| rows(input.0 + (p - r_us) as u32))
    };
    for p in 0..padded {
        let fresh = p % block == 0;
        let row = at(p);
        for w in 0..wpr {
            let v = row.map_or(0, |row| row[w]);
            from_start[p * wpr + w] = if fresh {
                v
            } else {
                from_start[(p - 1) * wpr + w] | v
            };
        }
    }
    for p in (0..padded).rev() {
        let fresh = p % block == block - 1 || p + 1 == padded;
        let row = at(p);
        for w in 0..wpr {
            let v = row.map_or(0, |row| row[w]);
            to_end[p * wpr + w] = if fresh {
                v
            } else {
                to_end[(p + 1) * wpr + w] | v
            };
        }
    }
    for y in out.0..=out.1 {
        // Row y's window starts at padded index (y - r) - input.0 + r = y - input.0.
        let k = (y - input.0) as usize;
        let end = k + 2 * r_us;
        counts[(y - out.0) as usize] = (0..wpr)
            .map(|w| (to_end[k * wpr + w] | from_start[end * wpr + w]).count_ones())
            .sum();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The grown set, cell by cell: every cell within `r` rows and columns of a set cell.
    fn reference(set: &CellSet, r: u32) -> u64 {
        let (nx, ny) = (set.nx() as i64, set.ny() as i64);
        let r = i64::from(r);
        let mut n = 0;
        for y in 0..ny {
            for x in 0..nx {
                let near = (y - r..=y + r).any(|j| {
                    (x - r..=x + r).any(|i| {
                        (0..nx).contains(&i)
                            && (0..ny).contains(&j)
                            && set.contains((i as u32, j as u32))
                    })
                });
                n += u64::from(near);
            }
        }
        n
    }

    fn set_of(grid: &GroundGrid, cells: &[(u32, u32)]) -> CellSet {
        let (nx, ny) = (grid.nx, grid.ny);
        CellSet::from_cells(grid, cells.iter().map(|&(x, y)| (x % nx, y % ny)))
    }

    #[test]
    fn rings_round_the_reach_to_whole_cells() {
        assert_eq!(rings(20.0, 2.5, 200), 8);
        assert_eq!(rings(30.0, 2.5, 200), 12);
        assert_eq!(rings(0.0, 2.5, 200), 0);
        assert_eq!(rings(f64::NAN, 2.5, 200), 0);
        assert_eq!(rings(1e9, 2.5, 200), 200);
    }

    #[test]
    fn a_straight_boundary_grows_by_r_cells_along_it_and_the_edges_add_nothing() {
        let grid = GroundGrid::new(50.0, 1.0); // 100 x 100
        let mut half = CellSet::empty(&grid);
        for y in 0..50 {
            half.fill_row_span(y, 0, 99);
        }
        assert_eq!(Growth::of(&half, 8).grown_cells(), 58 * 100);
        assert_eq!(Growth::of(&half, 0).grown_cells(), 50 * 100);
        assert_eq!(
            Growth::of(&CellSet::full(&grid), 5).grown_cells(),
            100 * 100
        );
        let far = Growth::of(&half, u32::MAX);
        assert_eq!(far.grown_cells(), 100 * 100);
        assert_eq!(far.grown_cells_after(&half, Some((0, 99))), 100 * 100);
    }

    /// Pockets closer than `2 r` grow into the same ground once: clearing the ground between
    /// them never raises the grown area, where the boundary charge (`r` per boundary cell)
    /// would.
    #[test]
    fn clearing_between_pockets_never_adds_growth() {
        let grid = GroundGrid::new(50.0, 1.0);
        let mut block = CellSet::empty(&grid);
        for y in 40..60 {
            block.fill_row_span(y, 40, 59);
        }
        let mut pockets = CellSet::empty(&grid);
        for (x, y) in [(42, 42), (48, 50), (55, 57), (58, 41)] {
            pockets.set((x, y), true);
        }
        let r = 8;
        assert!(Growth::of(&pockets, r).grown_cells() <= Growth::of(&block, r).grown_cells());
        let block_r = Growth::of(&block, r);
        let whole = Growth::of(&pockets, r).grown_cells();
        assert_eq!(block_r.grown_cells_after(&pockets, Some((40, 59))), whole);
        // Without growth, the count is the cells'.
        let block_0 = Growth::of(&block, 0);
        assert_eq!(block_0.grown_cells(), 400);
        assert_eq!(block_0.grown_cells_after(&pockets, Some((40, 59))), 4);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// The count equals the cell-by-cell grown set, for sets anywhere (the grid's edges
        /// and the words' edges too) and any rings.
        #[test]
        fn the_grown_cells_are_those_within_r_rows_and_columns(
            cells in proptest::collection::vec((0u32..130, 0u32..70), 0..40),
            r in 0u32..70,
        ) {
            let grid = GroundGrid::new(32.5, 0.5); // 130 x 130
            let set = set_of(&grid, &cells);
            prop_assert_eq!(Growth::of(&set, r).grown_cells(), reference(&set, r));
        }

        /// A set changed on some rows only, counted on their reach, has the count of the set
        /// grown whole; and removing cells never grows the count.
        #[test]
        fn the_count_after_a_change_is_the_whole_count(
            cells in proptest::collection::vec((0u32..130, 0u32..130), 1..60),
            removed in proptest::collection::vec(0usize..60, 0..30),
            r in 0u32..20,
        ) {
            let grid = GroundGrid::new(32.5, 0.5);
            let before = set_of(&grid, &cells);
            let mut after = before.clone();
            let mut rows: Option<(u32, u32)> = None;
            for i in removed {
                let (x, y) = cells[i % cells.len()];
                let (x, y) = (x % 130, y % 130);
                after.set((x, y), false);
                rows = Some(rows.map_or((y, y), |(a, b)| (a.min(y), b.max(y))));
            }
            let growth = Growth::of(&before, r);
            let whole = Growth::of(&after, r).grown_cells();
            prop_assert_eq!(growth.grown_cells_after(&after, rows), whole);
            prop_assert!(whole <= growth.grown_cells());
        }
    }
}
