//! Where a set lies: its bounding box, its barycentre, cropping and counting inside a box.

use super::{CellBox, CellSet};
use crate::grid::GroundGrid;
use crate::math::{Point2, Real};

impl CellSet {
    /// The smallest box holding every cell of the set, `None` when empty.
    pub fn bounding_box(&self) -> Option<CellBox> {
        self.bounding_box_within(0..self.ny)
    }

    /// The smallest box holding every cell of the set in rows `rows`, `None` when they hold
    /// none.
    pub fn bounding_box_within(&self, rows: std::ops::Range<u32>) -> Option<CellBox> {
        let (y0, y1) = self.row_range_within(rows)?;
        let mut x0 = u32::MAX;
        let mut x1 = 0;
        for iy in y0..=y1 {
            let row = self.row(iy);
            if let Some(w) = row.iter().position(|&w| w != 0) {
                x0 = x0.min(w as u32 * 64 + row[w].trailing_zeros());
            }
            if let Some(w) = row.iter().rposition(|&w| w != 0) {
                x1 = x1.max(w as u32 * 64 + 63 - row[w].leading_zeros());
            }
        }
        Some(CellBox { x0, y0, x1, y1 })
    }

    /// Removes every cell outside `bbox` (a box reaching past the grid is clamped to it; an
    /// inverted box removes everything).
    pub fn crop(&mut self, bbox: &CellBox) {
        let keep_rows = bbox.y0..=bbox.y1.min(self.ny.saturating_sub(1));
        let (x0, x1) = (bbox.x0, bbox.x1);
        let wpr = self.words_per_row.max(1);
        let first = self.first;
        for (iy, row) in (first..).zip(self.words.chunks_exact_mut(wpr)) {
            if !keep_rows.contains(&iy) || x0 > x1 {
                row.fill(0);
                continue;
            }
            for (w, word) in row.iter_mut().enumerate() {
                *word &= span_mask(w as u32, x0, x1);
            }
        }
        self.trim_rows();
    }

    /// One flag per cell of `window`, row-major: whether the cell is in the set; cells of the
    /// window outside the grid read `outside`.
    pub fn window_flags(&self, window: &CellBox, outside: bool) -> Vec<bool> {
        let mut out = Vec::with_capacity(window.cell_count() as usize);
        for iy in window.y0..=window.y1 {
            if iy >= self.ny {
                out.extend((window.x0..=window.x1).map(|_| outside));
                continue;
            }
            let row = self.row(iy);
            out.extend((window.x0..=window.x1).map(|ix| {
                if ix >= self.nx {
                    outside
                } else {
                    row[ix as usize / 64] >> (ix % 64) & 1 == 1
                }
            }));
        }
        out
    }

    /// Number of cells of the set inside `bbox` (clamped to the grid).
    pub fn count_in_box(&self, bbox: &CellBox) -> u64 {
        self.count_in_box_and(bbox, |_, _| u64::MAX)
    }

    /// Number of cells of `self ∩ other` inside `bbox` (clamped to the grid), without
    /// building the intersection.
    pub fn intersection_count_in_box(&self, other: &CellSet, bbox: &CellBox) -> u64 {
        debug_assert!(self.same_shape(other));
        self.count_in_box_and(bbox, |iy, w| other.row(iy)[w])
    }

    /// Number of cells of the set inside `bbox` whose bit is also set in `also(row, word)`.
    fn count_in_box_and(&self, bbox: &CellBox, also: impl Fn(u32, usize) -> u64) -> u64 {
        if bbox.x0 > bbox.x1 || bbox.y0 > bbox.y1 || bbox.y0 >= self.ny {
            return 0;
        }
        let (w0, w1) = (bbox.x0 as usize / 64, bbox.x1 as usize / 64);
        (bbox.y0..=bbox.y1.min(self.ny - 1))
            .map(|iy| {
                let row = self.row(iy);
                (w0..=w1.min(self.words_per_row.saturating_sub(1)))
                    .map(|w| {
                        let mask = span_mask(w as u32, bbox.x0, bbox.x1);
                        (row[w] & also(iy, w) & mask).count_ones() as u64
                    })
                    .sum::<u64>()
            })
            .sum()
    }

    /// Barycentre of the cell centres, `None` when empty.
    pub fn barycentre(&self, grid: &GroundGrid) -> Option<Point2> {
        let mut n = 0u64;
        let (mut sum_x, mut sum_y) = (0u128, 0u128);
        for iy in self.stored_rows() {
            let mut row_n = 0u64;
            for (w, &word) in self.row(iy).iter().enumerate() {
                if word == 0 {
                    continue;
                }
                let c = u64::from(word.count_ones());
                row_n += c;
                sum_x += u128::from(c * (w as u64 * 64) + bit_index_sum(word));
            }
            n += row_n;
            sum_y += u128::from(row_n) * u128::from(iy);
        }
        if n == 0 {
            return None;
        }
        let mean = |s: u128| s as Real / n as Real + 0.5;
        Some(Point2::new(
            grid.origin.x + mean(sum_x) * grid.cell_m,
            grid.origin.y + mean(sum_y) * grid.cell_m,
        ))
    }
}

/// The bits of word `w` whose column lies in `x0..=x1`.
fn span_mask(w: u32, x0: u32, x1: u32) -> u64 {
    let (lo, hi) = (u64::from(w) * 64, u64::from(w) * 64 + 63);
    let (x0, x1) = (u64::from(x0), u64::from(x1));
    if x1 < lo || x0 > hi || x0 > x1 {
        return 0;
    }
    let from = x0.max(lo) - lo;
    let to = x1.min(hi) - lo;
    (u64::MAX >> (63 - to)) & (u64::MAX << from)
}

/// Sum of the indices of the set bits of `word`: bit `k` of an index contributes `2^k` for
/// every set bit whose index has it, counted with one mask per `k`.
fn bit_index_sum(word: u64) -> u64 {
    const INDEX_BIT: [u64; 6] = [
        0xAAAA_AAAA_AAAA_AAAA,
        0xCCCC_CCCC_CCCC_CCCC,
        0xF0F0_F0F0_F0F0_F0F0,
        0xFF00_FF00_FF00_FF00,
        0xFFFF_0000_FFFF_0000,
        0xFFFF_FFFF_0000_0000,
    ];
    INDEX_BIT
        .iter()
        .enumerate()
        .map(|(k, m)| u64::from((word & m).count_ones()) << k)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> GroundGrid {
        GroundGrid::new(50.0, 1.0)
    }

    #[test]
    fn bounding_box_spans_words_and_rows() {
        let g = grid();
        assert_eq!(CellSet::empty(&g).bounding_box(), None);
        let s = CellSet::from_cells(&g, [(70, 3), (5, 9), (99, 4)]);
        assert_eq!(
            s.bounding_box(),
            Some(CellBox {
                x0: 5,
                y0: 3,
                x1: 99,
                y1: 9
            })
        );
    }

    #[test]
    fn crop_keeps_the_box_only() {
        let g = grid();
        let mut s = CellSet::full(&g);
        let b = CellBox {
            x0: 60,
            y0: 10,
            x1: 70,
            y1: 12,
        };
        s.crop(&b);
        assert_eq!(s.count(), 11 * 3);
        assert_eq!(s.bounding_box(), Some(b));
        assert_eq!(s.count_in_box(&b), 33);
        assert_eq!(
            s.count_in_box(&CellBox {
                x0: 0,
                y0: 0,
                x1: 64,
                y1: 99
            }),
            5 * 3
        );
        let mut t = CellSet::full(&g);
        t.crop(&CellBox {
            x0: 98,
            y0: 98,
            x1: 500,
            y1: 500,
        });
        assert_eq!(t.count(), 4);
        t.crop(&CellBox {
            x0: 3,
            y0: 0,
            x1: 2,
            y1: 99,
        });
        assert!(t.is_empty());
    }

    #[test]
    fn barycentre_is_the_mean_of_cell_centres() {
        let g = grid();
        assert_eq!(CellSet::empty(&g).barycentre(&g), None);
        let s = CellSet::from_cells(&g, [(0, 0), (99, 0), (63, 64)]);
        let b = s
            .barycentre(&g)
            .unwrap_or_else(|| Point2::new(Real::NAN, Real::NAN));
        let expect_x = -50.0 + (0.0 + 99.0 + 63.0) / 3.0 + 0.5;
        let expect_y = -50.0 + 64.0 / 3.0 + 0.5;
        assert!((b.x - expect_x).abs() < 1e-12 && (b.y - expect_y).abs() < 1e-12);
    }

    #[test]
    fn bit_index_sum_matches_a_loop() {
        for word in [
            0u64,
            1,
            u64::MAX,
            0x8000_0000_0000_0001,
            0xDEAD_BEEF_1234_5678,
        ] {
            let slow: u64 = (0..64).filter(|b| word >> b & 1 == 1).sum();
            assert_eq!(bit_index_sum(word), slow);
        }
    }
}
